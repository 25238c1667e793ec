"""One source-seeking episode in kinematic dynamics, and the registries the bench sweeps.

An *episode*: one algorithm (a behaviour plug-in on 1 or more vehicles), one environment (a
concentration field and its wind), one sensor model, one seeded start. Vehicles are point
masses that follow their setpoint exactly (a velocity setpoint is flown as given, capped at
``MAX_SPEED_M_S``; a position setpoint is approached at ``POSITION_GAIN_HZ``·distance, capped
likewise): the behaviours' decisions, not a controller's, make the result. The field is
sampled at every vehicle's position every ``sensor_period_ticks``; each vehicle's reading goes
through the scenario's sensor model (:class:`agents.sensor.ConcentrationSensor`) and carries
the field's values at its peers' positions, as on the bus.

Registries (:data:`ALGORITHMS`, :data:`ENVIRONMENTS`, :data:`SENSORS`) are plain dicts: add an
entry to add a row. An environment or sensor whose model this build lacks is listed with what
is missing, so the bench can say which cells it could not run.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import msgspec
import numpy as np
import numpy.typing as npt

from agents.behavior import Behavior, BehaviorContext, load_behavior
from agents.behaviors.search import PLUME_THRESHOLD_G_M3, SourceEstimate
from agents.sensor import ConcentrationSensor
from plume_service.from_scenario import field_from_scenario
from swarmbus.messages import PeerReading, Setpoint, VehicleState
from swarmbus.plume_formula import downwind_unit
from swarmbus.scenario import Scenario, Sensor, Vehicle, load_scenario

FloatArray = npt.NDArray[np.float64]
Field = Callable[[FloatArray, float], FloatArray]

MAX_SPEED_M_S = 5.0
POSITION_GAIN_HZ = 1.0
SUCCESS_RADIUS_M = 2.0
START_ALONG_M = (30.0, 80.0)  # downwind of the source
START_ACROSS_M = (-20.0, 20.0)
START_ALTITUDE_M = 10.0
TRAJECTORY_EVERY_S = 0.5  # trajectory samples kept for the figure


@dataclass(frozen=True)
class Algorithm:
    behavior: str  # "module:Class"
    vehicles: int = 1
    source: str = ""  # the publication it follows


ALGORITHMS: dict[str, Algorithm] = {
    "random_walk": Algorithm(
        "agents.behaviors.random_walk:RandomWalk", 1, "Codling et al. 2008 (baseline)"
    ),
    "casting": Algorithm("agents.behaviors.casting:Casting", 1, "Kennedy & Marsh 1974"),
    "surge_cast": Algorithm(
        "agents.behaviors.surge_cast:SurgeCast", 1, "Lochmatter & Martinoli 2008"
    ),
    "gradient_swarm": Algorithm(
        "agents.behaviors.gradient_swarm:GradientSwarm", 3, "Ögren, Fiorelli & Leonard 2004"
    ),
    "infotaxis": Algorithm(
        "agents.behaviors.infotaxis:Infotaxis", 1, "Vergassola, Villermaux & Shraiman 2007"
    ),
    "particle_filter": Algorithm(
        "agents.behaviors.particle_filter:ParticleFilter", 1, "Hutchinson, Oh & Chen 2017"
    ),
}


@dataclass(frozen=True)
class Environment:
    """A plume condition: ``build(scenario)`` gives its field, or ``missing`` says what this
    build lacks to simulate it."""

    description: str
    build: Callable[[Scenario], Field] | None = None
    missing: str | None = None


def _steady_gaussian(scenario: Scenario) -> Field:
    plume = field_from_scenario(scenario)
    return lambda points, t: plume.concentration(points, t)


_FILAMENTS = "the filament plume model and the vehicle anemometer"
ENVIRONMENTS: dict[str, Environment] = {
    "steady_gaussian": Environment("steady Gaussian plume (the scenario's)", _steady_gaussian),
    "filaments": Environment("filament plume without meander", missing=_FILAMENTS),
    "meander_small": Environment("filament plume, small wind meander", missing=_FILAMENTS),
    "meander_large": Environment("filament plume, large wind meander", missing=_FILAMENTS),
}


@dataclass(frozen=True)
class SensorModel:
    description: str
    config: Sensor | None = None
    missing: str | None = None


SENSORS: dict[str, SensorModel] = {
    "ideal": SensorModel("the field's value, no lag, noise or limits", Sensor(preset="ideal")),
    "mox": SensorModel("metal-oxide sensor (TGS2620-like)", missing="the MOX sensor model"),
}


@dataclass(frozen=True)
class EpisodeSpec:
    algorithm: str
    environment: str
    sensor: str
    run: int
    seed: int
    time_limit_s: float = 300.0
    control_hz: int = 20
    sensor_period_ticks: int = 2
    keep_trajectory: bool = False


@dataclass
class Outcome:
    spec: EpisodeSpec
    success: bool
    time_to_success_s: float | None
    path_length_m: float
    initial_distance_m: float
    final_error_m: float
    detections_per_min: float
    declared: bool
    estimate_xy: tuple[float, float]
    trajectories: list[list[tuple[float, float]]] = field(default_factory=list)


def start_point(scenario: Scenario, seed: int, run: int) -> tuple[float, float]:
    """Run ``run``'s start (ENU): uniform 30–80 m downwind and ±20 m crosswind of the source.
    The same for every algorithm, so that cells are compared on the same starts."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, run, 0x57A7])))
    along = float(rng.uniform(*START_ALONG_M))
    across = float(rng.uniform(*START_ACROSS_M))
    src = scenario.plume.sources[0]
    dw = downwind_unit(scenario.wind.from_deg)
    cw = (-dw[1], dw[0])
    return src.x_m + along * dw[0] + across * cw[0], src.y_m + along * dw[1] + across * cw[1]


def episode_scenario(base: Scenario, spec: EpisodeSpec) -> Scenario:
    algo = ALGORITHMS[spec.algorithm]
    sensor = SENSORS[spec.sensor].config
    assert sensor is not None
    sensor = msgspec.structs.replace(sensor, period_ticks=spec.sensor_period_ticks)
    vehicles = [
        Vehicle(id=f"uav{i + 1}", behavior=algo.behavior, mission=[]) for i in range(algo.vehicles)
    ]
    world = msgspec.structs.replace(base.world, seed=spec.seed)
    return msgspec.structs.replace(base, world=world, sensor=sensor, vehicles=vehicles)


def _follow(setpoint: Setpoint | None, p: list[float]) -> tuple[float, float, float]:
    """The point mass's velocity for a setpoint (None: hover)."""
    if setpoint is None:
        return 0.0, 0.0, 0.0
    if setpoint.velocity_enu_m_s is not None:
        v = setpoint.velocity_enu_m_s
    elif setpoint.position_enu_m is not None:
        t = setpoint.position_enu_m
        v = tuple(POSITION_GAIN_HZ * (t[i] - p[i]) for i in range(3))  # type: ignore[assignment]
    else:
        return 0.0, 0.0, 0.0
    speed = math.sqrt(v[0] ** 2 + v[1] ** 2 + v[2] ** 2)
    if speed > MAX_SPEED_M_S:
        k = MAX_SPEED_M_S / speed
        return v[0] * k, v[1] * k, v[2] * k
    return v[0], v[1], v[2]


def _state(
    vehicle_id: str, tick: int, t: float, p: list[float], v: tuple[float, ...]
) -> VehicleState:
    return VehicleState(
        vehicle_id=vehicle_id,
        tick=tick,
        sim_time_s=t,
        position_enu_m=(p[0], p[1], p[2]),
        velocity_enu_m_s=(v[0], v[1], v[2]),
        attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
        body_rates_rad_s=(0.0, 0.0, 0.0),
        lat_deg=0.0,
        lon_deg=0.0,
        alt_m=p[2],
        on_ground=False,
    )


def behavior_rng(spec: EpisodeSpec, vehicle_index: int) -> np.random.Generator:
    salt = zlib.crc32(spec.algorithm.encode())
    ss = np.random.SeedSequence([spec.seed, spec.run, vehicle_index, salt])
    return np.random.Generator(np.random.PCG64(ss))


def run_episode(spec: EpisodeSpec, base: Scenario | None = None) -> Outcome:
    """Fly one episode to its declaration or its time limit; deterministic in ``spec``."""
    base = base if base is not None else load_scenario()
    env = ENVIRONMENTS[spec.environment]
    assert env.build is not None
    scenario = episode_scenario(base, spec)
    concentration = env.build(scenario)
    dt = 1.0 / spec.control_hz
    src = scenario.plume.sources[0]
    sx, sy = start_point(scenario, spec.seed, spec.run)
    n = len(scenario.vehicles)
    positions = [[sx, sy, START_ALTITUDE_M] for _ in range(n)]
    if n > 1:  # a swarm starts on a circle of 2 m around the start point
        for i, p in enumerate(positions):
            angle = 2.0 * math.pi * i / n
            p[0] += 2.0 * math.cos(angle)
            p[1] += 2.0 * math.sin(angle)
    velocities = [(0.0, 0.0, 0.0)] * n
    behaviors: list[Behavior] = []
    sensors = []
    for i, v in enumerate(scenario.vehicles):
        ctx = BehaviorContext(v.id, i, scenario, dt, behavior_rng(spec, i))
        behaviors.append(load_behavior(v.behavior or "", ctx))
        sensors.append(ConcentrationSensor(scenario.sensor, spec.seed * 100_003 + spec.run, i))
    ids = [v.id for v in scenario.vehicles]
    path = [0.0] * n
    detections = 0
    first_inside_s: float | None = None
    declared: SourceEstimate | None = None
    keep_every = max(1, round(TRAJECTORY_EVERY_S / dt))
    tracks: list[list[tuple[float, float]]] = [[(p[0], p[1])] for p in positions]
    ticks = round(spec.time_limit_s * spec.control_hz)
    tick = 0
    for tick in range(ticks):
        t = tick * dt
        states = [_state(ids[i], tick, t, positions[i], velocities[i]) for i in range(n)]
        readings: list[list] = [[] for _ in range(n)]  # type: ignore[type-arg]
        if tick % spec.sensor_period_ticks == 0:
            values = concentration(np.array(positions, dtype=np.float64), t)
            for i in range(n):
                peers = [
                    PeerReading(
                        vehicle_id=ids[j],
                        position_enu_m=(positions[j][0], positions[j][1], positions[j][2]),
                        true_g_m3=float(values[j]),
                    )
                    for j in range(n)
                    if j != i
                ]
                r = sensors[i].reading(ids[i], t, states[i].position_enu_m, float(values[i]), peers)
                if r.reported_g_m3 is not None and r.reported_g_m3 >= PLUME_THRESHOLD_G_M3:
                    detections += 1
                readings[i].append(r)
        for i, b in enumerate(behaviors):
            others = states[:i] + states[i + 1 :]
            velocities[i] = _follow(b.step(states[i], others, readings[i]), positions[i])
        for i, p in enumerate(positions):
            vel = velocities[i]
            p[0] += vel[0] * dt
            p[1] += vel[1] * dt
            p[2] += vel[2] * dt
            path[i] += math.hypot(vel[0], vel[1]) * dt
            if spec.keep_trajectory and tick % keep_every == 0:
                tracks[i].append((p[0], p[1]))
        cx = sum(p[0] for p in positions) / n
        cy = sum(p[1] for p in positions) / n
        if first_inside_s is None and math.hypot(cx - src.x_m, cy - src.y_m) <= SUCCESS_RADIUS_M:
            first_inside_s = t + dt
        declared = next(
            (d for b in behaviors if (d := getattr(b, "declaration", None)) is not None), None
        )
        if declared is not None:
            break
    elapsed_s = (tick + 1) * dt
    if declared is not None:
        estimate = (declared.x_m, declared.y_m)
    else:
        estimate = (
            sum(p[0] for p in positions) / n,
            sum(p[1] for p in positions) / n,
        )
    error = math.hypot(estimate[0] - src.x_m, estimate[1] - src.y_m)
    success = error <= SUCCESS_RADIUS_M
    if declared is not None:
        time_s: float | None = declared.sim_time_s if success else None
    else:
        time_s = first_inside_s if success else None
    initial = math.hypot(sx - src.x_m, sy - src.y_m)
    mean_path = sum(path) / n
    return Outcome(
        spec=spec,
        success=success,
        time_to_success_s=time_s,
        path_length_m=mean_path,
        initial_distance_m=initial,
        final_error_m=error,
        detections_per_min=detections / n / (elapsed_s / 60.0),
        declared=declared is not None,
        estimate_xy=estimate,
        trajectories=tracks if spec.keep_trajectory else [],
    )
