"""Where a sensor can see a scenario's plume: the region where the time-averaged field is above
the sensor's detection floor (``plumeswarm plume visibility``).

The time-averaged field is the steady Gaussian plume of the scenario's atmosphere (its wind,
stability, dispersion coefficients, mixing lid and sources, whatever plume model the scenario
itself runs: the filament and puff plumes meander around that mean). The floor is
:attr:`agents.sensor.ConcentrationSensor.floor_g_m3` of the chosen sensor at the scenario's
temperature and pressure; ``margin`` asks for the region where the mean is at least that many
times the floor (a detection threshold some noise above the floor).

Reported, at one flight altitude: the farthest (and nearest) downwind distance from the first
source, on its axis, where the mean is at least ``margin`` × floor, and the crosswind
half-width of that region at given downwind distances. A sensor with no floor (``ideal``)
sees the plume everywhere it is non-zero: its reach is unbounded (``math.inf``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import msgspec
import numpy as np

from agents.sensor import ConcentrationSensor
from plume_atmosphere.plume_formula import downwind_unit
from plume_service.field import ConcentrationField
from plume_service.from_scenario import field_from_scenario
from swarmbus.scenario import Scenario, Sensor

#: The crosswind distances (m downwind of the source) reported by default.
DEFAULT_DISTANCES_M = (30.0, 50.0, 80.0)
#: How far downwind (and crosswind) the search looks (m).
MAX_RANGE_M = 20_000.0
_AXIS_SAMPLES = 20_000
_BISECTIONS = 60


@dataclass(frozen=True)
class Visibility:
    """The region of a scenario's mean plume a sensor can see at one altitude."""

    floor_g_m3: float
    noise_std_g_m3: float
    level_g_m3: float  # margin × floor: what the mean must reach
    altitude_m: float
    nearest_m: float | None  # downwind distance on the axis; None: never above the level
    farthest_m: float | None  # math.inf: unbounded (no floor)
    half_width_m: dict[float, float]  # downwind distance → crosswind half-width (0: none)
    centreline_g_m3: dict[float, float]  # downwind distance → the mean on the axis


def steady_field(scenario: Scenario) -> ConcentrationField:
    """The scenario's time-averaged field: every source as a steady Gaussian plume."""
    sources = [msgspec.structs.replace(s, model=None) for s in scenario.plume.sources]
    plume = msgspec.structs.replace(scenario.plume, model="gaussian", sources=sources)
    return field_from_scenario(msgspec.structs.replace(scenario, plume=plume))


def sensor_of(scenario: Scenario, sensor: Sensor | None = None) -> ConcentrationSensor:
    """The sensor (default: the scenario's own) at the scenario's temperature and pressure."""
    world = scenario.world
    config = scenario.sensor if sensor is None else sensor
    return ConcentrationSensor(config, world.seed, 0, world.temperature_k, world.pressure_pa)


def default_altitude_m(scenario: Scenario) -> float:
    """The middle of the ``[env]`` start box's heights: where searches fly."""
    return 0.5 * (scenario.env.start_min_enu_m[2] + scenario.env.start_max_enu_m[2])


def floor_multiple(
    scenario: Scenario, sensor: Sensor | None, point_enu_m: Sequence[float]
) -> float:
    """The scenario's mean concentration at ``point_enu_m`` in multiples of the sensor's floor
    (``math.inf`` for a sensor without a floor and a non-zero mean)."""
    mean = float(steady_field(scenario).concentration([tuple(point_enu_m)])[0])
    floor = sensor_of(scenario, sensor).floor_g_m3
    if floor <= 0.0:
        return math.inf if mean > 0.0 else 0.0
    return mean / floor


def visibility(
    scenario: Scenario,
    sensor: Sensor | None = None,
    altitude_m: float | None = None,
    distances_m: Sequence[float] = DEFAULT_DISTANCES_M,
    margin: float = 1.0,
) -> Visibility:
    """Where ``sensor`` (default: the scenario's) sees the scenario's mean plume at
    ``altitude_m`` (default :func:`default_altitude_m`): see the module docstring."""
    if not (math.isfinite(margin) and margin > 0.0):
        raise ValueError(f"margin must be a positive number, got {margin}")
    z = default_altitude_m(scenario) if altitude_m is None else altitude_m
    if not (math.isfinite(z) and z >= 0.0):
        raise ValueError(f"altitude must be a number >= 0 m, got {z}")
    if any(not (math.isfinite(d) and d > 0.0) for d in distances_m):
        raise ValueError(f"downwind distances must be positive numbers, got {list(distances_m)}")
    field = steady_field(scenario)
    model = sensor_of(scenario, sensor)
    level = margin * model.floor_g_m3
    axis = _Axis(field, scenario, z)
    centreline = {d: float(axis.along(np.array([d]))[0]) for d in distances_m}
    nearest: float | None
    farthest: float | None
    if level <= 0.0:  # no floor: any gas at all is seen
        nearest, farthest = 0.0, math.inf
        widths = {d: math.inf if centreline[d] > 0.0 else 0.0 for d in distances_m}
    else:
        nearest, farthest = _reach(axis.along, level)
        widths = {d: _half_width(axis, d, level) for d in distances_m}
    return Visibility(
        floor_g_m3=model.floor_g_m3,
        noise_std_g_m3=model.noise_std_g_m3,
        level_g_m3=level,
        altitude_m=z,
        nearest_m=nearest,
        farthest_m=farthest,
        half_width_m=widths,
        centreline_g_m3=centreline,
    )


class _Axis:
    """The field along the first source's downwind axis and across it, at one height."""

    def __init__(self, field: ConcentrationField, scenario: Scenario, z_m: float) -> None:
        source = scenario.plume.sources[0]
        self.field = field
        self.origin = (source.x_m, source.y_m)
        self.down = downwind_unit(scenario.wind.from_deg)
        self.z_m = z_m

    def at(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        (ux, uy), (x0, y0) = self.down, self.origin
        east = x0 + x_m * ux - y_m * uy  # y: crosswind, to the left of the wind
        north = y0 + x_m * uy + y_m * ux
        points = np.column_stack([east, north, np.full(x_m.shape, self.z_m)])
        return np.asarray(self.field.concentration(points), dtype=np.float64)

    def along(self, x_m: np.ndarray) -> np.ndarray:
        return self.at(x_m, np.zeros_like(x_m))


def _reach(
    profile: Callable[[np.ndarray], np.ndarray], level: float
) -> tuple[float | None, float | None]:
    """The nearest and farthest distance in (0, MAX_RANGE_M] where ``profile`` ≥ ``level``."""
    grid = np.geomspace(0.01, MAX_RANGE_M, _AXIS_SAMPLES)
    values = profile(grid)
    above = np.flatnonzero((values >= level) & (values > 0.0))
    if above.size == 0:
        return None, None
    first, last = int(above[0]), int(above[-1])
    nearest = (
        0.0 if first == 0 else _crossing(profile, level, float(grid[first - 1]), float(grid[first]))
    )
    if last == grid.size - 1:
        return nearest, math.inf
    return nearest, _crossing(profile, level, float(grid[last + 1]), float(grid[last]))


def _crossing(
    profile: Callable[[np.ndarray], np.ndarray], level: float, below: float, above: float
) -> float:
    """Where ``profile`` crosses ``level`` between a point ``below`` it and one ``above``."""
    for _ in range(_BISECTIONS):
        middle = 0.5 * (below + above)
        if float(profile(np.array([middle]))[0]) >= level:
            above = middle
        else:
            below = middle
    return 0.5 * (below + above)


def _half_width(axis: _Axis, x_m: float, level: float) -> float:
    """The largest crosswind |y| at ``x_m`` downwind where the mean is ≥ ``level``."""
    widths = []
    for side in (1.0, -1.0):

        def across(y: np.ndarray, side: float = side) -> np.ndarray:
            return axis.at(np.full(y.shape, x_m), side * y)

        _, farthest = _reach(across, level)
        widths.append(0.0 if farthest is None else farthest)
    return max(widths)
