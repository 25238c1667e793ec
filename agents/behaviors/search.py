"""What the source-seeking behaviours share: the wind input, the declared estimate, the frame.

**The wind input.** A behaviour reads the wind through ``self.read_wind(own)``, a
:data:`WindReader` returning the air velocity (east, north) in m/s at the vehicle. Built with
:func:`anemometer_wind` it is the vehicle's anemometer (:class:`agents.anemometer.Anemometer`:
the scenario's wind at the vehicle's position and the state's sim time, plus the
``[anemometer]`` noise seeded by (scenario seed, vehicle index, tick)) — the reading the
autopilot process publishes on ``vehicle/<id>/wind``, the same bits in every runner.
:func:`scenario_wind` (the scenario's mean ``[wind]``, noiseless) is kept for tests.

**Detection.** :class:`PlumeDetector` says whether a reading is a detection: a level
threshold for a fast sensor, the rise between two samples for a slow-recovery (metal-oxide)
sensor; :func:`detector_for` picks by the scenario's sensor model.

**The declaration.** A behaviour that decides where the source is sets ``self.declaration``
to a :class:`SourceEstimate` (once; it then holds position). Runners read it; the bench
``plumeswarm bench gsl`` scores the declared position instead of where the vehicle ends.

**Snapshots.** A behaviour (and each helper it keeps, such as :class:`CrosswindSweep`) derives
from :class:`SavesState` and lists its state attributes in ``state_attributes``; its
``snapshot()`` / ``restore(data)`` save and put back exactly those (numpy arrays and generators
bit for bit), never its configuration or the callables it was built with (``read_wind``), so a
restarted autopilot's behaviour flies on with the same bits.
"""

from __future__ import annotations

import dataclasses
import math
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from agents.anemometer import Anemometer
from agents.behavior import BehaviorContext
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState
from swarmbus.plume_formula import downwind_unit
from swarmbus.wind import wind_from_scenario

#: (east, north) air velocity in m/s at the vehicle, as an anemometer would measure it.
WindReader = Callable[[VehicleState], tuple[float, float]]

#: A reading at or above this (g/m³) counts as "in the plume" (a detection) for the strategies
#: that need a binary signal. 0.001 g/m³ makes the steady novak2018 plume ≈ ±8 m wide at 50 m
#: downwind and reach beyond 100 m on its axis.
PLUME_THRESHOLD_G_M3 = 0.001


def scenario_wind(ctx: BehaviorContext) -> WindReader:
    """The scenario's ``[wind]`` as a :data:`WindReader` (the stand-in for an anemometer)."""
    ux, uy = downwind_unit(ctx.scenario.wind.from_deg)
    speed = ctx.scenario.wind.speed_m_s
    wind = (speed * ux, speed * uy)
    return lambda own: wind


def anemometer_wind(ctx: BehaviorContext) -> WindReader:
    """The vehicle's anemometer as a :data:`WindReader`: read at the state's tick, sim time
    and position (what the autopilot process publishes for that tick)."""
    scenario = ctx.scenario
    wind = wind_from_scenario(scenario)
    anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, ctx.vehicle_index)
    vehicle_id = ctx.vehicle_id

    def read(own: VehicleState) -> tuple[float, float]:
        r = anemometer.read(vehicle_id, own.tick, own.sim_time_s, own.position_enu_m)
        return r.wind_enu_m_s[0], r.wind_enu_m_s[1]

    return read


@dataclass(frozen=True)
class WindFrame:
    """Unit vectors downwind and crosswind (to the left of the wind) from a wind vector."""

    downwind: tuple[float, float]
    crosswind: tuple[float, float]
    speed_m_s: float

    @classmethod
    def of(cls, wind_east_north_m_s: tuple[float, float]) -> WindFrame:
        east, north = wind_east_north_m_s
        speed = math.hypot(east, north)
        if speed <= 1e-9:  # calm: any frame serves; keep the last convention (toward +x)
            return cls((1.0, 0.0), (0.0, 1.0), 0.0)
        dw = (east / speed, north / speed)
        return cls(dw, (-dw[1], dw[0]), speed)

    def velocity(self, along_m_s: float, across_m_s: float) -> tuple[float, float]:
        """ENU (east, north) velocity of ``along`` downwind plus ``across`` crosswind."""
        dw, cw = self.downwind, self.crosswind
        return along_m_s * dw[0] + across_m_s * cw[0], along_m_s * dw[1] + across_m_s * cw[1]

    def coordinates(self, east_m: float, north_m: float) -> tuple[float, float]:
        """(along, across) coordinates of an ENU point in this frame (origin at the ENU origin)."""
        dw, cw = self.downwind, self.crosswind
        return east_m * dw[0] + north_m * dw[1], east_m * cw[0] + north_m * cw[1]


@dataclass(frozen=True)
class SourceEstimate:
    """Where a behaviour believes the source is: ENU metres, the release rate if it estimates
    one, the 1-σ horizontal spread of its belief if it has one, and when it decided."""

    x_m: float
    y_m: float
    sim_time_s: float
    release_rate_g_s: float | None = None
    spread_m: float | None = None


class SavesState:
    """``snapshot()`` / ``restore(data)`` over the attributes named in ``state_attributes``.

    The data is plain msgpack-encodable values; tuples, deques, numpy arrays (dtype, shape
    and bytes), generators (their ``bit_generator.state``), :class:`SourceEstimate` and
    nested :class:`SavesState` objects are tagged so that restoring gives back the same types
    and bits. A nested object or generator is restored into the one the fresh behaviour built
    (which keeps its configuration).
    """

    state_attributes: ClassVar[tuple[str, ...]] = ()

    def snapshot(self) -> dict[str, Any]:
        return {name: encode_state(getattr(self, name)) for name in self.state_attributes}

    def restore(self, data: dict[str, Any]) -> None:
        for name in self.state_attributes:
            if name not in data:
                raise ValueError(f"{type(self).__name__} snapshot: no {name!r} in it")
            setattr(self, name, decode_state(data[name], getattr(self, name)))


def _encode_int(value: int) -> Any:
    # msgpack holds 64 bits; a generator's 128-bit words go as decimal text
    return value if -(2**63) <= value < 2**64 else {"$": "int", "v": str(value)}


def _tagged(tag: str, value: Any) -> dict[str, Any]:
    return {"$": tag, "v": value}


#: How each kind of value is saved, in the order the kinds are tried (bool before int).
_ENCODERS: tuple[tuple[type | tuple[type, ...], Callable[[Any], Any]], ...] = (
    ((bool, str, float, type(None)), lambda v: v),
    (int, _encode_int),
    (SavesState, lambda v: _tagged("state", v.snapshot())),
    (np.ndarray, lambda v: _tagged("ndarray", [v.dtype.str, list(v.shape), v.tobytes()])),
    (np.random.Generator, lambda v: _tagged("generator", encode_state(v.bit_generator.state))),
    (SourceEstimate, lambda v: _tagged("estimate", encode_state(dataclasses.asdict(v)))),
    (tuple, lambda v: _tagged("tuple", [encode_state(x) for x in v])),
    (deque, lambda v: _tagged("deque", [encode_state(x) for x in v])),
    (list, lambda v: [encode_state(x) for x in v]),
)


def encode_state(value: Any) -> Any:
    """``value`` as msgpack-encodable data that :func:`decode_state` turns back exactly."""
    for kind, encode in _ENCODERS:
        if isinstance(value, kind):
            return encode(value)
    if isinstance(value, dict) and all(isinstance(k, str) for k in value):
        return _tagged("dict", {k: encode_state(v) for k, v in value.items()})
    raise TypeError(f"cannot save a {type(value).__name__} as behaviour state")


def _restore_into(current: Any, v: Any) -> Any:
    current.restore(v)
    return current


def _generator_into(current: Any, v: Any) -> Any:
    current.bit_generator.state = decode_state(v)
    return current


def _ndarray(v: Any) -> Any:
    dtype, shape, raw = v
    return np.frombuffer(raw, dtype=np.dtype(dtype)).reshape(shape).copy()


#: The tagged kinds: tag -> (saved value, the fresh attribute) -> value.
_DECODERS: dict[str, Callable[[Any, Any], Any]] = {
    "int": lambda v, current: int(v),
    "state": lambda v, current: _restore_into(current, v),
    "ndarray": lambda v, current: _ndarray(v),
    "generator": lambda v, current: _generator_into(current, v),
    "estimate": lambda v, current: SourceEstimate(**decode_state(v)),
    "tuple": lambda v, current: tuple(decode_state(x) for x in v),
    "deque": lambda v, current: deque(decode_state(x) for x in v),
    "dict": lambda v, current: {k: decode_state(x) for k, x in v.items()},
}


def decode_state(data: Any, current: Any = None) -> Any:
    """The value :func:`encode_state` saved; ``current`` (the fresh attribute) receives a
    nested state or a generator's state in place."""
    if isinstance(data, list):
        return [decode_state(v) for v in data]
    if not isinstance(data, dict):
        return data
    tag, v = data["$"], data["v"]
    decoder = _DECODERS.get(tag)
    if decoder is None:
        raise ValueError(f"behaviour snapshot: unknown value kind {tag!r}")
    return decoder(v, current)


def valid_values(readings: Sequence[ConcentrationReading]) -> list[tuple[float, float, float]]:
    """(x, y, reported g/m³) of the readings that are available."""
    return [
        (r.position_enu_m[0], r.position_enu_m[1], r.reported_g_m3)
        for r in readings
        if r.available and r.reported_g_m3 is not None
    ]


def fly(
    own: VehicleState, velocity_en_m_s: tuple[float, float], altitude_m: float, gain: float = 1.0
) -> Setpoint:
    """A velocity setpoint: horizontal as given, vertical holding ``altitude_m``."""
    vz = gain * (altitude_m - own.position_enu_m[2])
    return Setpoint(velocity_enu_m_s=(velocity_en_m_s[0], velocity_en_m_s[1], vz))


def hold_at(x_m: float, y_m: float, altitude_m: float) -> Setpoint:
    """A position setpoint over a point at ``altitude_m`` (after a declaration)."""
    return Setpoint(position_enu_m=(x_m, y_m, altitude_m))


def start_or_hold(
    own: VehicleState, altitude_m: float | None, declaration: SourceEstimate | None
) -> tuple[float, Setpoint | None]:
    """The altitude a search flies at (the vehicle's own at its first step) and, once the
    source is declared, the setpoint that holds over the declaration."""
    altitude = own.position_enu_m[2] if altitude_m is None else altitude_m
    if declaration is None:
        return altitude, None
    return altitude, hold_at(declaration.x_m, declaration.y_m, altitude)


def toward(own: VehicleState, x_m: float, y_m: float, speed_m_s: float) -> tuple[float, float]:
    """Horizontal velocity toward (x, y) at ``speed_m_s``, slowing inside the last metre."""
    dx, dy = x_m - own.position_enu_m[0], y_m - own.position_enu_m[1]
    dist = math.hypot(dx, dy)
    if dist < 1e-9:
        return 0.0, 0.0
    speed = min(speed_m_s, dist)
    return speed * dx / dist, speed * dy / dist


#: A sensor whose decay time constant is longer than this (s) recovers too slowly for a level
#: threshold: after one burst its reading stays above the threshold for minutes.
SLOW_DECAY_S = 5.0


class PlumeDetector(SavesState):
    """Whether each reading is a detection ("in the plume"), one sample after another.

    ``level``: the reading is at least ``threshold_g_m3``. ``rise``: the reading rose by at
    least ``threshold_g_m3`` (and above 0) since the previous sample — for a slow-recovery
    sensor, which rises while gas arrives (rise time constant) and decays slowly after it
    (a metal-oxide sensor's 15.71 s keeps one burst above 0.001 g/m³ for ≈ 2 min), so a
    level says little about now but a rise does. Give it the available readings only.
    """

    state_attributes = ("previous_g_m3",)

    def __init__(self, mode: str = "level", threshold_g_m3: float = 0.0) -> None:
        if mode not in ("level", "rise"):
            raise ValueError(f"detector mode {mode!r}: valid: level, rise")
        self.mode = mode
        self.threshold_g_m3 = threshold_g_m3
        self.previous_g_m3: float | None = None

    def hit(self, value_g_m3: float) -> bool:
        previous, self.previous_g_m3 = self.previous_g_m3, value_g_m3
        if self.mode == "level":
            return value_g_m3 > 0.0 and value_g_m3 >= self.threshold_g_m3
        if previous is None:
            return False
        rise = value_g_m3 - previous
        return rise > 0.0 and rise >= self.threshold_g_m3


def detector_for(ctx: BehaviorContext, level_g_m3: float = PLUME_THRESHOLD_G_M3) -> PlumeDetector:
    """The detector for the scenario's sensor: a level of ``level_g_m3`` for a fast sensor;
    for a slow-recovery one (decay time constant > :data:`SLOW_DECAY_S`) a rise, per sample,
    of what a sensor in clean air shows in one sample on meeting ``level_g_m3``:
    ``level_g_m3`` × (1 − exp(−sample period / rise time constant))."""
    sensor = ctx.scenario.sensor.resolved()
    if sensor.decay_s <= SLOW_DECAY_S:
        return PlumeDetector("level", level_g_m3)
    period_s = sensor.period_ticks / ctx.scenario.time.control_hz
    rise = -math.expm1(-period_s / sensor.rise_s) if sensor.rise_s > 0.0 else 1.0
    return PlumeDetector("rise", level_g_m3 * rise)


class BestReadingDeclarer(SavesState):
    """The stopping rule of casting and surge-cast: the source is where the strongest reading
    was taken, once the plume has been lost ``losses_to_declare`` times in a row without that
    place moving more than ``settle_m`` — the searcher keeps overshooting the same spot — and
    the strongest reading is at least ``growth_to_declare`` times the first detection.

    In a plume from a point source the mean concentration is largest next to the source, and
    a searcher that surges past the source loses the plume there (upwind of a source there is
    no gas), so repeated losses with no better reading mean it has arrived. The growth
    condition tells that apart from losing the plume's edge far downwind, where the readings
    stay close to the first one. Detections are readings above 0 and at least
    ``detection_g_m3``.
    """

    state_attributes = ("first_g_m3", "best_g_m3", "best_xy", "_at_last_loss", "settled_losses")

    def __init__(
        self,
        detection_g_m3: float = 0.0,
        losses_to_declare: int = 2,
        settle_m: float = 1.0,
        growth_to_declare: float = 5.0,
    ) -> None:
        self.detection_g_m3 = detection_g_m3
        self.losses_to_declare = losses_to_declare
        self.settle_m = settle_m
        self.growth_to_declare = growth_to_declare
        self.first_g_m3: float | None = None
        self.best_g_m3 = 0.0
        self.best_xy: tuple[float, float] | None = None
        self._at_last_loss: tuple[float, float] | None = None
        self.settled_losses = 0

    def observe(self, x_m: float, y_m: float, value_g_m3: float) -> None:
        if value_g_m3 <= 0.0 or value_g_m3 < self.detection_g_m3:
            return
        if self.first_g_m3 is None:
            self.first_g_m3 = value_g_m3
        if value_g_m3 > self.best_g_m3:
            self.best_g_m3 = value_g_m3
            self.best_xy = (x_m, y_m)

    def lost(self, sim_time_s: float) -> SourceEstimate | None:
        """Call once per loss of the plume; the estimate when the rule fires, else None."""
        best, last = self.best_xy, self._at_last_loss
        if best is None or self.first_g_m3 is None:
            return None
        if last is not None and math.dist(best, last) <= self.settle_m:
            self.settled_losses += 1
        else:
            self.settled_losses = 0
        self._at_last_loss = best
        grown = self.best_g_m3 >= self.growth_to_declare * self.first_g_m3
        if grown and self.settled_losses + 1 >= self.losses_to_declare:
            return SourceEstimate(x_m=best[0], y_m=best[1], sim_time_s=sim_time_s)
        return None


class CrosswindSweep(SavesState):
    """Crosswind legs of growing width around an anchor line, drifting along the wind: the
    search pattern of casting, surge-cast and the plume-less phases of the other strategies.

    Each leg ends ``half_width_m`` from the anchor (the crosswind coordinate where the sweep
    began); at its end the vehicle turns and the half-width grows by ``growth`` up to
    ``max_half_width_m``. ``drift_m_s`` > 0 drifts downwind, < 0 upwind.
    """

    state_attributes = ("side", "anchor_across_m", "half_width_m")

    def __init__(
        self,
        speed_m_s: float,
        drift_m_s: float,
        first_half_width_m: float,
        growth: float,
        max_half_width_m: float = 40.0,
        side: float = 1.0,
    ) -> None:
        self.speed_m_s = speed_m_s
        self.drift_m_s = drift_m_s
        self.first_half_width_m = first_half_width_m
        self.growth = growth
        self.max_half_width_m = max_half_width_m
        self.side = side
        self.anchor_across_m: float | None = None
        self.half_width_m = first_half_width_m

    def restart(self) -> None:
        """The next call starts a new sweep around where the vehicle is then."""
        self.anchor_across_m = None

    def velocity(self, frame: WindFrame, x_m: float, y_m: float) -> tuple[float, float]:
        _, across = frame.coordinates(x_m, y_m)
        if self.anchor_across_m is None:
            self.anchor_across_m = across
            self.half_width_m = self.first_half_width_m
        if (across - self.anchor_across_m) * self.side > self.half_width_m:
            self.side = -self.side
            self.half_width_m = min(self.half_width_m * self.growth, self.max_half_width_m)
        return frame.velocity(self.drift_m_s, self.speed_m_s * self.side)
