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

from agents.anemometer import Anemometer
from agents.behavior import Behavior, BehaviorContext, load_behavior
from agents.behaviors.search import PLUME_THRESHOLD_G_M3, SourceEstimate
from agents.sensor import ConcentrationSensor
from plume_service.from_scenario import field_from_scenario
from swarmbus.messages import ConcentrationReading, PeerReading, Setpoint, VehicleState
from swarmbus.plume_formula import downwind_unit
from swarmbus.scenario import Scenario, Sensor, Vehicle, load_scenario
from swarmbus.wind import WindModel, wind_from_scenario

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
    """A plume condition: the scenario's plume model and wind model for the episode.

    ``plume = "gaussian"`` is the scenario's steady plume, its behaviours read the scenario's
    wind. Any other model is time-dependent: its field and wind are deterministic functions of
    (scenario, seed, t), every episode starts ``FIELD_WARMUP_S`` of sim time after the release
    began, and the behaviours read the wind from their anemometer
    (:class:`agents.anemometer.Anemometer`, the same wind, the scenario's noise)."""

    description: str
    plume: str = "gaussian"  # [plume] model
    meander: str | None = None  # [wind.meander] preset; None: the scenario's steady wind
    missing: str | None = None

    @property
    def time_dependent(self) -> bool:
        return self.plume != "gaussian"


#: Sim time the release runs before an episode starts in a time-dependent environment: the
#: filaments reach beyond the farthest start (80 m at the novak2018 wind of 6 m/s in 14 s).
FIELD_WARMUP_S = 60.0

ENVIRONMENTS: dict[str, Environment] = {
    "steady_gaussian": Environment("steady Gaussian plume (the scenario's)"),
    "filaments": Environment("filament plume in a steady wind", "filament"),
    "meander_small": Environment("filament plume, small wind meander", "filament", "small"),
    "meander_large": Environment("filament plume, large wind meander", "filament", "large"),
}


def environment_scenario(scenario: Scenario, environment: str) -> Scenario:
    """``scenario`` with the environment's plume and wind models."""
    env = ENVIRONMENTS[environment]
    if not env.time_dependent:
        return scenario
    wind = scenario.wind
    if env.meander is not None:
        meander = msgspec.structs.replace(wind.meander, preset=env.meander).resolved()
        wind = msgspec.structs.replace(wind, model="meander", meander=meander)
    else:
        wind = msgspec.structs.replace(wind, model="steady")
    sources = [msgspec.structs.replace(s, model=None) for s in scenario.plume.sources]
    plume = msgspec.structs.replace(scenario.plume, model=env.plume, sources=sources)
    return msgspec.structs.replace(scenario, wind=wind, plume=plume)


def environment_field(scenario: Scenario) -> tuple[Field, WindModel]:
    """The episode scenario's field (g/m³ at points, sim time t) and the one wind it uses."""
    wind = wind_from_scenario(scenario)
    plume = field_from_scenario(scenario, wind)
    return (lambda points, t: plume.concentration(points, t)), wind


@dataclass(frozen=True)
class SensorModel:
    description: str
    config: Sensor | None = None
    missing: str | None = None


SENSORS: dict[str, SensorModel] = {
    "ideal": SensorModel("the field's value, no lag, noise or limits", Sensor(preset="ideal")),
    "mox": SensorModel(
        "metal-oxide sensor, Figaro TGS2620 (rise 2.96 s, decay 15.71 s)",
        Sensor(preset="mox-tgs2620"),
    ),
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
    dynamics: str = "kinematic"  # or "full"


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
    # A time-dependent field draws its own realisation for each run.
    seed = spec.seed
    if ENVIRONMENTS[spec.environment].time_dependent:
        seed = spec.seed * 100_003 + spec.run
    world = msgspec.structs.replace(base.world, seed=seed)
    time = msgspec.structs.replace(base.time, control_hz=spec.control_hz)
    scenario = msgspec.structs.replace(
        base, world=world, time=time, sensor=sensor, vehicles=vehicles
    )
    return environment_scenario(scenario, spec.environment)


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


class KinematicFlight:
    """Point masses that fly their behaviour's setpoint."""

    def __init__(
        self,
        scenario: Scenario,
        behaviors: list[Behavior],
        starts: list[list[float]],
        dt: float,
        start_tick: int = 0,
    ) -> None:
        self.ids = [v.id for v in scenario.vehicles]
        self.behaviors = behaviors
        self.positions = [list(p) for p in starts]
        self.velocities = [(0.0, 0.0, 0.0)] * len(starts)
        self.dt = dt
        self.start_tick = start_tick

    def states(self, tick: int, t: float) -> list[VehicleState]:
        return [
            _state(self.ids[i], tick, t, p, self.velocities[i])
            for i, p in enumerate(self.positions)
        ]

    def act(
        self,
        i: int,
        own: VehicleState,
        peers: list[VehicleState],
        readings: list[ConcentrationReading],
    ) -> None:
        self.velocities[i] = _follow(
            self.behaviors[i].step(own, peers, readings), self.positions[i]
        )

    def advance(self) -> None:
        for p, v in zip(self.positions, self.velocities, strict=True):
            p[0] += v[0] * self.dt
            p[1] += v[1] * self.dt
            p[2] += v[2] * self.dt

    def close(self) -> None:
        pass


class FullFlight:
    """The real vehicles: pybullet physics (:class:`sim_world.world.World`) and one
    :class:`agents.autopilot.Autopilot` per vehicle running its behaviour in offboard mode,
    stepped in lockstep in this process. Each vehicle is armed on the ground at its start,
    takes off to the start altitude, and is switched to offboard once all hover within
    ``altitude_tolerance_m`` of it; the episode starts then, or at sim time ``start_s`` if
    that is later (the vehicles hover till then)."""

    takeoff_timeout_s = 60.0
    altitude_tolerance_m = 0.03

    def __init__(
        self,
        scenario: Scenario,
        behaviors: list[Behavior],
        starts: list[list[float]],
        start_s: float = 0.0,
    ):
        from agents.autopilot import Autopilot
        from sim_world.world import World

        vehicles = [
            msgspec.structs.replace(v, spawn_enu_m=(p[0], p[1], 0.0))
            for v, p in zip(scenario.vehicles, starts, strict=True)
        ]
        self.scenario = msgspec.structs.replace(scenario, vehicles=vehicles)
        self.ids = [v.id for v in vehicles]
        self.world = World(self.scenario)
        self.autopilots = [
            Autopilot(self.scenario, vid, behavior=b)
            for vid, b in zip(self.ids, behaviors, strict=True)
        ]
        self.substeps = self.scenario.substeps
        self.dt = 1.0 / self.scenario.time.control_hz
        self.tick = 0
        self._take_off(starts[0][2])
        self._run_ticks(max(0, round(start_s / self.dt) - self.tick))  # hover until start_s
        self.start_tick = self.tick

    def _run_ticks(self, count: int) -> None:
        for _ in range(count):
            states = self.states(self.tick, self.tick * self.dt)
            for i, state in enumerate(states):
                self.act(i, state, states[:i] + states[i + 1 :], [])
            self.advance()

    def _take_off(self, altitude_m: float) -> None:
        from swarmbus.messages import Arm, FlightMode, SetMode, Takeoff

        self._run_ticks(2)
        for ap in self.autopilots:
            for cmd in (Arm(), Takeoff(altitude_m=altitude_m)):
                reply = ap.handle(cmd)
                if not reply.accepted:
                    raise RuntimeError(f"{ap.vehicle_id}: {type(cmd).__name__}: {reply.reason}")
        deadline = self.tick + round(self.takeoff_timeout_s / self.dt)
        # Hovering, and at the start altitude: the take-off hands over to hold within 0.3 m of
        # it, and the behaviours keep the altitude they begin at.
        while any(ap.modes.mode != FlightMode.HOLD for ap in self.autopilots) or any(
            abs(s.position_enu_m[2] - altitude_m) > self.altitude_tolerance_m
            for s in self.states(self.tick, self.tick * self.dt)
        ):
            if self.tick > deadline:
                raise RuntimeError(
                    f"vehicles not hovering at {altitude_m} m after {self.takeoff_timeout_s} s"
                )
            self._run_ticks(1)
        for ap in self.autopilots:
            reply = ap.handle(SetMode(mode=FlightMode.OFFBOARD))
            if not reply.accepted:
                raise RuntimeError(f"{ap.vehicle_id}: offboard: {reply.reason}")

    def states(self, tick: int, t: float) -> list[VehicleState]:
        return self.world.states(tick, t)

    def act(
        self,
        i: int,
        own: VehicleState,
        peers: list[VehicleState],
        readings: list[ConcentrationReading],
    ) -> None:
        self.world.apply(self.ids[i], self.autopilots[i].step(own, peers, readings))

    def advance(self) -> None:
        self.world.step(self.substeps)
        self.tick += 1

    def close(self) -> None:
        self.world.close()


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
    assert env.missing is None
    scenario = episode_scenario(base, spec)
    concentration, wind = environment_field(scenario)
    start_s = FIELD_WARMUP_S if env.time_dependent else 0.0
    src = scenario.plume.sources[0]
    sx, sy = start_point(scenario, spec.seed, spec.run)
    n = len(scenario.vehicles)
    starts = [[sx, sy, START_ALTITUDE_M] for _ in range(n)]
    if n > 1:  # a swarm starts on a circle of 2 m around the start point
        for i, p in enumerate(starts):
            angle = 2.0 * math.pi * i / n
            p[0] += 2.0 * math.cos(angle)
            p[1] += 2.0 * math.sin(angle)
    dt = 1.0 / spec.control_hz
    behaviors = episode_behaviors(spec, scenario, wind)
    sensors = [
        ConcentrationSensor(scenario.sensor, spec.seed * 100_003 + spec.run, i) for i in range(n)
    ]
    flight: KinematicFlight | FullFlight
    if spec.dynamics == "full":
        flight = FullFlight(scenario, behaviors, starts, start_s)
    else:
        flight = KinematicFlight(scenario, behaviors, starts, dt, round(start_s / dt))
    try:
        return _fly(spec, flight, behaviors, sensors, concentration, (sx, sy), (src.x_m, src.y_m))
    finally:
        flight.close()


def episode_behaviors(spec: EpisodeSpec, scenario: Scenario, wind: WindModel) -> list[Behavior]:
    """The episode's behaviours; in a time-dependent environment each reads ``wind`` through
    its vehicle's anemometer instead of the scenario's mean wind."""
    dt = 1.0 / spec.control_hz
    behaviors = []
    for i, v in enumerate(scenario.vehicles):
        ctx = BehaviorContext(v.id, i, scenario, dt, behavior_rng(spec, i))
        behavior = load_behavior(v.behavior or "", ctx)
        if ENVIRONMENTS[spec.environment].time_dependent and hasattr(behavior, "read_wind"):
            behavior.read_wind = _anemometer_reader(scenario, wind, i, v.id)
        behaviors.append(behavior)
    return behaviors


def _anemometer_reader(
    scenario: Scenario, wind: WindModel, index: int, vehicle_id: str
) -> Callable[[VehicleState], tuple[float, float]]:
    """A behaviour's ``read_wind``: the vehicle's anemometer at its state's tick and position."""
    anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, index)

    def read(own: VehicleState) -> tuple[float, float]:
        r = anemometer.read(vehicle_id, own.tick, own.sim_time_s, own.position_enu_m)
        return r.wind_enu_m_s[0], r.wind_enu_m_s[1]

    return read


def _fly(
    spec: EpisodeSpec,
    flight: KinematicFlight | FullFlight,
    behaviors: list[Behavior],
    sensors: list[ConcentrationSensor],
    concentration: Field,
    start: tuple[float, float],
    source: tuple[float, float],
) -> Outcome:
    ids = flight.ids
    dt = flight.dt
    n = len(ids)
    period = sensors[0].config.period_ticks
    t0 = flight.start_tick * dt
    path = [0.0] * n
    detections = 0
    first_inside_s: float | None = None
    declared: SourceEstimate | None = None
    keep_every = max(1, round(TRAJECTORY_EVERY_S / dt))
    tracks: list[list[tuple[float, float]]] = [[] for _ in range(n)]
    previous: list[tuple[float, float, float]] | None = None
    ticks = round(spec.time_limit_s / dt)
    k = 0
    for k in range(ticks):
        tick = flight.start_tick + k
        t = tick * dt
        states = flight.states(tick, t)
        positions = [s.position_enu_m for s in states]
        if previous is not None:
            for i, (p, q) in enumerate(zip(positions, previous, strict=True)):
                path[i] += math.hypot(p[0] - q[0], p[1] - q[1])
        previous = positions
        if spec.keep_trajectory and k % keep_every == 0:
            for i, p in enumerate(positions):
                tracks[i].append((p[0], p[1]))
        cx = sum(p[0] for p in positions) / n
        cy = sum(p[1] for p in positions) / n
        if first_inside_s is None and math.dist((cx, cy), source) <= SUCCESS_RADIUS_M:
            first_inside_s = t - t0
        readings: list[list[ConcentrationReading]] = [[] for _ in range(n)]
        if tick % period == 0:
            values = concentration(np.array(positions, dtype=np.float64), t)
            for i in range(n):
                peers = [
                    PeerReading(
                        vehicle_id=ids[j], position_enu_m=positions[j], true_g_m3=float(values[j])
                    )
                    for j in range(n)
                    if j != i
                ]
                r = sensors[i].reading(ids[i], t, positions[i], float(values[i]), peers)
                if r.reported_g_m3 is not None and r.reported_g_m3 >= PLUME_THRESHOLD_G_M3:
                    detections += 1
                readings[i].append(r)
        for i in range(n):
            flight.act(i, states[i], states[:i] + states[i + 1 :], readings[i])
        flight.advance()
        declared = next(
            (d for b in behaviors if (d := getattr(b, "declaration", None)) is not None), None
        )
        if declared is not None:
            break
    elapsed_s = (k + 1) * dt
    final = flight.states(flight.start_tick + k + 1, t0 + elapsed_s)
    if previous is not None:
        for i, (s, q) in enumerate(zip(final, previous, strict=True)):
            path[i] += math.hypot(s.position_enu_m[0] - q[0], s.position_enu_m[1] - q[1])
    if declared is not None:
        estimate = (declared.x_m, declared.y_m)
    else:
        estimate = (
            sum(s.position_enu_m[0] for s in final) / n,
            sum(s.position_enu_m[1] for s in final) / n,
        )
    error = math.dist(estimate, source)
    success = error <= SUCCESS_RADIUS_M
    if declared is not None:
        time_s: float | None = declared.sim_time_s - t0 if success else None
    else:
        time_s = first_inside_s if success else None
    initial = math.dist(start, source)
    return Outcome(
        spec=spec,
        success=success,
        time_to_success_s=time_s,
        path_length_m=sum(path) / n,
        initial_distance_m=initial,
        final_error_m=error,
        detections_per_min=detections / n / (elapsed_s / 60.0),
        declared=declared is not None,
        estimate_xy=estimate,
        trajectories=tracks if spec.keep_trajectory else [],
    )
