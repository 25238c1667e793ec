"""One source-seeking episode, in either dynamics, and the registries the bench sweeps.

An *episode*: one algorithm (a behaviour plug-in on 1 or more vehicles), one environment (a
concentration field and its wind), one sensor model, one seeded start — all of it a scenario
(:func:`episode_scenario`). Two ways to fly it:

- ``kinematic`` (:func:`kinematic_episode`): point masses that follow their setpoint exactly (a
  velocity setpoint is flown as given, capped at ``MAX_SPEED_M_S``; a position setpoint is
  approached at ``POSITION_GAIN_HZ``·distance, capped likewise): the behaviours' decisions,
  not a controller's, make the result. The field is sampled at every vehicle's position every
  ``sensor_period_ticks``; each vehicle's reading goes through its sensor model and carries the
  field's values at its peers' positions, as on the bus, and reaches the behaviour that tick.
  What a vehicle learns of its peers (their states, their samples, their behaviours' messages)
  passes through the scenario's ``[radio]`` (:class:`agents.peer_link.PeerLink`).
- ``full`` (:func:`fused_episode`): the scenario driven through the in-process driver
  (:class:`plumeswarm.experiments.driver.InProcessDriver`, the fused runner of
  :mod:`plumeswarm.experiments.fused`)
  — the distributed stack's physics, autopilots, sensors and plume, the same bits; a take-off
  and an offboard switch at recorded tick boundaries (:class:`Schedule`), so the same episode
  can be flown on the distributed stack.

What an episode flies — the algorithm, the environment file, the sensor — comes from
:mod:`plumeswarm.gsl.registry`; where it starts, how long it may fly, the warm-up of a
time-dependent release and what counts as finding the source are the protocol's, here.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from agents.behavior import Behavior, BehaviorContext, SourceEstimate, load_behavior
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3
from agents.build import behavior_rng
from agents.peer_link import PeerLink
from agents.sensor import ConcentrationSensor
from plume_atmosphere.plume_formula import downwind_unit
from plume_atmosphere.wind import WindModel, wind_from_scenario
from plume_service.from_scenario import field_from_scenario
from plume_service.statistics import warmup_s
from plumeswarm.experiments.driver import InProcessDriver
from plumeswarm.experiments.fused import StatesObserver
from plumeswarm.gsl.family import AUTO_TIME_LIMIT_MULTIPLE, straight_flight_limit_s
from plumeswarm.gsl.registry import (
    SENSORS,
    Algorithm,
    Environment,
    algorithm_from_spec,
    load_environment,
    resolve_algorithm,
    time_dependent,
)
from swarmbus.messages import (
    Arm,
    Command,
    ConcentrationReading,
    FlightMode,
    PeerReading,
    SetMode,
    Setpoint,
    Takeoff,
    VehicleState,
)
from swarmbus.scenario import Scenario, VehicleSpec

FloatArray = npt.NDArray[np.float64]
Field = Callable[[FloatArray, float], FloatArray]
Point = tuple[float, float]

MAX_SPEED_M_S = 5.0
POSITION_GAIN_HZ = 1.0
SUCCESS_RADIUS_M = 2.0
RADII_M = (2.0, 5.0)  # "reached within r" and "declared within r"
START_ALONG_M = (30.0, 80.0)  # downwind of the source
START_ACROSS_M = (-20.0, 20.0)
START_ALTITUDE_M = 10.0
TRAJECTORY_EVERY_S = 0.5  # trajectory samples kept for the figure


#: The shortest time the release runs before an episode starts in a time-dependent
#: environment (:func:`start_s`; longer in a wind under 2 m/s).
FIELD_WARMUP_S = 60.0


def environment_of(spec: EpisodeSpec) -> Environment:
    """The spec's environment file, loaded with its overrides."""
    return load_environment(spec.environment, spec.overrides)


def episode_environment(spec: EpisodeSpec) -> Scenario:
    """The world the episode flies in: the environment's scenario or, in a randomised family
    (:mod:`plumeswarm.gsl.family`), its base with run (seed, run)'s draw, calibrated."""
    env = environment_of(spec)
    if env.family is None:
        return env.scenario
    return env.family.scenario(env.scenario, spec.seed, spec.run)


def start_distances_m(spec: EpisodeSpec) -> tuple[float, float]:
    """The nearest and farthest start from the source the episode's environment may draw
    (the warm-up covers the farthest): a family's ``start_distance_m``, else the spec's."""
    family = environment_of(spec).family
    return family.start_distance_m if family is not None else spec.start_along_m


def episode_start(spec: EpisodeSpec, scenario: Scenario) -> Point:
    """Where run ``spec.run`` starts (ENU): :func:`start_point` or, in a randomised family,
    the drawn start relative to the drawn source and wind (``scenario``: the episode's)."""
    family = environment_of(spec).family
    if family is None:
        return start_point(scenario, spec.seed, spec.run, spec.start_along_m)
    return _at(scenario, *family.draw(spec.seed, spec.run).start_along_across_m)


def episode_time_limit_s(spec: EpisodeSpec, scenario: Scenario | None = None) -> float:
    """``--time-limit auto``'s limit for the episode: a randomised family's own
    (:attr:`plumeswarm.gsl.family.Draw.time_limit_s`), else ``AUTO_TIME_LIMIT_MULTIPLE`` × the
    straight flight from the run's start to the source at ``SEARCH_SPEED_M_S``."""
    family = environment_of(spec).family
    if family is not None:
        return family.draw(spec.seed, spec.run).time_limit_s
    world = scenario if scenario is not None else episode_environment(spec)
    src = world.plume.sources[0]
    distance = math.dist(episode_start(spec, world), (src.x_m, src.y_m))
    return straight_flight_limit_s(distance, AUTO_TIME_LIMIT_MULTIPLE)


def environment_field(scenario: Scenario) -> tuple[Field, WindModel]:
    """The episode scenario's field (g/m³ at points, sim time t) and the one wind it uses."""
    wind = wind_from_scenario(scenario)
    plume = field_from_scenario(scenario, wind)
    return (lambda points, t: plume.concentration(points, t)), wind


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
    behavior: str = ""  # "module:Class" to fly; "": the registered algorithm's
    vehicles: int = 0  # how many fly it; 0: the algorithm's
    overrides: tuple[tuple[str, Any], ...] = ()  # "section.key" of the environment's scenario
    start_along_m: tuple[float, float] = START_ALONG_M
    start_spacing_m: float | None = None  # a swarm's crosswind spacing; None: the algorithm's

    def algorithm_config(self) -> Algorithm:
        if self.behavior:
            return Algorithm(self.behavior, self.vehicles or 1)
        return resolve_algorithm(self.algorithm)[1]

    def spacing_m(self) -> float:
        """The crosswind spacing of a swarm's starts (0: a circle of 2 m)."""
        if self.start_spacing_m is not None:
            return self.start_spacing_m
        if self.behavior:
            return algorithm_from_spec(self.behavior).start_spacing_m
        return self.algorithm_config().start_spacing_m


@dataclass
class Outcome:
    """One episode. ``success``: a declaration within ``SUCCESS_RADIUS_M`` of the source;
    ``time_to_success_s`` its time from the episode's start. ``final_error_m``: the
    declaration's distance from the source, or (none) where the vehicles (their centroid)
    end. ``first_within_s[i]``: when the centroid first came within ``RADII_M[i]``.
    ``closest_approach_m``: the least distance (3-D) between two vehicles at any tick;
    ``nearest_member_m``: the least horizontal distance of any one vehicle to the source."""

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
    start_xy: tuple[float, float] = (0.0, 0.0)
    min_distance_m: float = math.inf
    first_within_s: tuple[float | None, ...] = ()
    declared_s: float | None = None
    closest_approach_m: float | None = None  # between two vehicles (None: one vehicle)
    total_path_m: float = 0.0  # every vehicle's path, summed
    nearest_member_m: float = math.inf  # the closest any one vehicle came to the source


def start_point(
    scenario: Scenario, seed: int, run: int, along_m: tuple[float, float] = START_ALONG_M
) -> tuple[float, float]:
    """Run ``run``'s start (ENU): uniform 30–80 m (``along_m``) downwind and ±20 m crosswind
    of the source. The same for every algorithm, so that cells are compared on the same
    starts."""
    rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, run, 0x57A7])))
    along = float(rng.uniform(*along_m))
    across = float(rng.uniform(*START_ACROSS_M))
    return _at(scenario, along, across)


def _at(scenario: Scenario, along: float, across: float) -> Point:
    """The point ``along`` downwind of the first source and ``across`` to the left of the
    downwind direction (ENU)."""
    src = scenario.plume.sources[0]
    dw = downwind_unit(scenario.wind.from_deg)
    cw = (-dw[1], dw[0])
    return src.x_m + along * dw[0] + across * cw[0], src.y_m + along * dw[1] + across * cw[1]


def episode_starts(scenario: Scenario, spec: EpisodeSpec, count: int) -> list[list[float]]:
    """Where each vehicle starts (ENU, at ``START_ALTITUDE_M``): run ``spec.run``'s start; a
    swarm on a crosswind line centred on it, ``spec.spacing_m()`` apart (vehicle i at
    (i − (N − 1)/2) × spacing to the left of the mean wind), or — spacing 0 — on a circle of
    2 m around it."""
    sx, sy = episode_start(spec, scenario)
    starts = [[sx, sy, START_ALTITUDE_M] for _ in range(count)]
    spacing = spec.spacing_m() if count > 1 else 0.0
    if spacing > 0.0:
        dw = downwind_unit(scenario.wind.from_deg)
        cw = (-dw[1], dw[0])
        for i, p in enumerate(starts):
            offset = (i - (count - 1) / 2.0) * spacing
            p[0] += offset * cw[0]
            p[1] += offset * cw[1]
    elif count > 1:
        for i, p in enumerate(starts):
            angle = 2.0 * math.pi * i / count
            p[0] += 2.0 * math.cos(angle)
            p[1] += 2.0 * math.sin(angle)
    return starts


def episode_scenario(spec: EpisodeSpec, environment: Scenario | None = None) -> Scenario:
    """The episode as a scenario: the environment's (``environment``, default the spec's
    file with its overrides) with the algorithm's behaviour on each vehicle, spawned on the
    ground under its start, the sensor, and the run's own seed (seed × 100003 + run: the
    sensors' noise, the anemometers, the behaviours' generators and a time-dependent field's
    realisation). Any runner of the scenario flies the same episode."""
    base = environment if environment is not None else episode_environment(spec)
    algo = spec.algorithm_config()
    sensor = msgspec.structs.replace(
        SENSORS[spec.sensor].config, period_ticks=spec.sensor_period_ticks
    )
    starts = episode_starts(base, spec, algo.vehicles)
    vehicles = [
        VehicleSpec(
            id=f"uav{i + 1}", behavior=algo.behavior, mission=[], spawn_enu_m=(p[0], p[1], 0.0)
        )
        for i, p in enumerate(starts)
    ]
    world = msgspec.structs.replace(base.world, seed=spec.seed * 100_003 + spec.run)
    time = msgspec.structs.replace(base.time, control_hz=spec.control_hz)
    wind = msgspec.structs.replace(base.wind, meander=base.wind.meander.resolved())
    return msgspec.structs.replace(
        base, world=world, time=time, wind=wind, sensor=sensor, vehicles=vehicles
    )


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


def episode_behaviors(
    spec: EpisodeSpec, scenario: Scenario, link: PeerLink | None = None
) -> list[Behavior]:
    """The episode's behaviours, built as an autopilot process builds them (same context,
    same generator): each reads the wind from its vehicle's anemometer; with ``link``, each
    gets its mailbox on that radio."""
    dt = 1.0 / spec.control_hz
    return [
        load_behavior(
            v.behavior or "",
            BehaviorContext(
                v.id,
                i,
                scenario,
                dt,
                behavior_rng(scenario, v.id),
                link.mailboxes[v.id] if link is not None else None,
            ),
        )
        for i, v in enumerate(scenario.vehicles)
    ]


def declaration_of(behaviors: Sequence[object]) -> SourceEstimate | None:
    """The first declaration among the behaviours, if any."""
    return next((d for b in behaviors if (d := getattr(b, "declaration", None)) is not None), None)


class Tally:
    """What an episode measures as it flies: path, track, first arrival, detections."""

    def __init__(
        self, spec: EpisodeSpec, n: int, dt: float, t0: float, start: Point, source: Point
    ) -> None:
        self.spec, self.n, self.t0 = spec, n, t0
        self.start, self.source = start, source
        self.path = [0.0] * n
        self.detections = 0
        self.first_within_s: list[float | None] = [None] * len(RADII_M)
        self.min_distance_m = math.inf
        self.keep_every = max(1, round(TRAJECTORY_EVERY_S / dt))
        self.tracks: list[list[tuple[float, float]]] = [[] for _ in range(n)]
        self.previous: list[tuple[float, float, float]] | None = None
        self.count = 0
        self.closest_m = math.inf
        self.nearest_m = math.inf

    def observe(self, t: float, positions: Sequence[tuple[float, float, float]]) -> None:
        """Every vehicle's position at sim time ``t`` (one call per control tick)."""
        if self.previous is not None:
            for i, (p, q) in enumerate(zip(positions, self.previous, strict=True)):
                self.path[i] += math.hypot(p[0] - q[0], p[1] - q[1])
        self.previous = list(positions)
        for i in range(1, self.n):
            for j in range(i):
                self.closest_m = min(self.closest_m, math.dist(positions[i], positions[j]))
        if self.spec.keep_trajectory and self.count % self.keep_every == 0:
            for i, p in enumerate(positions):
                self.tracks[i].append((p[0], p[1]))
        self.count += 1
        cx = sum(p[0] for p in positions) / self.n
        cy = sum(p[1] for p in positions) / self.n
        distance = math.dist((cx, cy), self.source)
        self.min_distance_m = min(self.min_distance_m, distance)
        for p in positions:
            self.nearest_m = min(self.nearest_m, math.dist((p[0], p[1]), self.source))
        for i, r in enumerate(RADII_M):
            if self.first_within_s[i] is None and distance <= r:
                self.first_within_s[i] = t - self.t0

    def reading(self, reading: ConcentrationReading) -> None:
        value = reading.reported_g_m3
        if value is not None and value >= PLUME_THRESHOLD_G_M3:
            self.detections += 1

    def outcome(self, elapsed_s: float, declared: SourceEstimate | None) -> Outcome:
        """The episode's result; the last :meth:`observe` was where the vehicles end."""
        assert self.previous is not None
        final = self.previous
        if declared is not None:
            estimate = (declared.x_m, declared.y_m)
        else:
            estimate = (
                sum(p[0] for p in final) / self.n,
                sum(p[1] for p in final) / self.n,
            )
        error = math.dist(estimate, self.source)
        declared_s = None if declared is None else declared.sim_time_s - self.t0
        success = declared is not None and error <= SUCCESS_RADIUS_M
        return Outcome(
            spec=self.spec,
            success=success,
            time_to_success_s=declared_s if success else None,
            path_length_m=sum(self.path) / self.n,
            initial_distance_m=math.dist(self.start, self.source),
            final_error_m=error,
            detections_per_min=self.detections / self.n / (elapsed_s / 60.0),
            declared=declared is not None,
            estimate_xy=estimate,
            trajectories=self.tracks if self.spec.keep_trajectory else [],
            start_xy=self.start,
            min_distance_m=self.min_distance_m,
            first_within_s=tuple(self.first_within_s),
            declared_s=declared_s,
            closest_approach_m=self.closest_m if self.n > 1 else None,
            total_path_m=sum(self.path),
            nearest_member_m=self.nearest_m,
        )


def run_episode(spec: EpisodeSpec, environment: Scenario | None = None) -> Outcome:
    """Fly one episode to its declaration or its time limit; deterministic in ``spec``
    (``environment``: the scenario to fly in instead of the spec's environment file)."""
    if spec.dynamics == "full":
        return fused_episode(spec, environment)[0]
    return kinematic_episode(spec, environment)


def _tally(spec: EpisodeSpec, scenario: Scenario, dt: float, t0: float) -> Tally:
    src = scenario.plume.sources[0]
    return Tally(
        spec,
        len(scenario.vehicles),
        dt,
        t0,
        episode_start(spec, scenario),
        (src.x_m, src.y_m),
    )


def kinematic_episode(spec: EpisodeSpec, environment: Scenario | None = None) -> Outcome:
    """The episode with point masses; the field sampled here, each reading handed to its
    behaviour on the tick it is sampled."""
    scenario = episode_scenario(spec, environment)
    concentration, _ = environment_field(scenario)
    dt = 1.0 / spec.control_hz
    start_tick = round(start_s(scenario, start_distances_m(spec)) / dt)
    ids = [v.id for v in scenario.vehicles]
    link = PeerLink(scenario)
    behaviors = episode_behaviors(spec, scenario, link)
    sensors = [ConcentrationSensor.for_vehicle(scenario, i) for i in range(len(ids))]
    positions = episode_starts(scenario, spec, len(ids))
    velocities = [(0.0, 0.0, 0.0)] * len(ids)
    tally = _tally(spec, scenario, dt, start_tick * dt)
    period = scenario.sensor.period_ticks
    declared: SourceEstimate | None = None
    k = 0
    for k in range(round(spec.time_limit_s / dt)):
        tick = start_tick + k
        t = tick * dt
        states = [
            _state(vid, tick, t, p, velocities[i])
            for i, (vid, p) in enumerate(zip(ids, positions, strict=True))
        ]
        tally.observe(t, [s.position_enu_m for s in states])
        link.before_step(tick)
        peers = link.peers(tick, states)
        readings = None
        if tick % period == 0:
            readings = link.readings(tick, states, _sample(tally, sensors, states, concentration))
        for i, b in enumerate(behaviors):
            own = [readings[i]] if readings is not None else []
            setpoint = b.step(states[i], peers[i], own)
            velocities[i] = _follow(setpoint, positions[i])
        link.after_step(tick, states)
        for p, v in zip(positions, velocities, strict=True):
            p[0] += v[0] * dt
            p[1] += v[1] * dt
            p[2] += v[2] * dt
        declared = declaration_of(behaviors)
        if declared is not None:
            break
    tally.observe((start_tick + k + 1) * dt, [(p[0], p[1], p[2]) for p in positions])
    return tally.outcome((k + 1) * dt, declared)


def _sample(
    tally: Tally,
    sensors: list[ConcentrationSensor],
    states: list[VehicleState],
    concentration: Field,
) -> list[ConcentrationReading]:
    """Every vehicle's reading of this sensor tick (peers' field values attached, as on the
    bus)."""
    positions = [s.position_enu_m for s in states]
    t = states[0].sim_time_s
    values = concentration(np.array(positions, dtype=np.float64), t)
    everyone = [
        PeerReading(vehicle_id=s.vehicle_id, position_enu_m=s.position_enu_m, true_g_m3=float(v))
        for s, v in zip(states, values, strict=True)
    ]
    readings = []
    for i, (sensor, s) in enumerate(zip(sensors, states, strict=True)):
        peers = everyone[:i] + everyone[i + 1 :]
        r = sensor.reading(s.vehicle_id, t, s.position_enu_m, float(values[i]), peers)
        tally.reading(r)
        readings.append(r)
    return readings


def start_s(scenario: Scenario, along_m: tuple[float, float] = START_ALONG_M) -> float:
    """When the episode starts: in a time-dependent environment once its field is in its
    statistically steady state out to the farthest start — max(``FIELD_WARMUP_S``, 1.5 ×
    farthest start / mean wind speed) of release (:func:`plume_service.statistics.warmup_s`),
    60 s at 6 m/s, 120 s at 1 m/s — at once in a steady one."""
    if not time_dependent(scenario):
        return 0.0
    return max(FIELD_WARMUP_S, warmup_s(scenario, (along_m[1],)))


#: Commands given at tick boundaries: {tick: [(vehicle, command)]}; given when the runner
#: stands at that tick, each takes effect on the next.
Boundary = dict[int, list[tuple[str, Command]]]


@dataclass(frozen=True)
class Schedule:
    """What a full-dynamics episode did, enough to fly it again on any runner of the same
    scenario: the commands at their tick boundaries and the last tick."""

    scenario: Scenario
    commands: Boundary
    last_tick: int


class FusedEpisode:
    """A full-dynamics episode driven through an
    :class:`~plumeswarm.experiments.driver.InProcessDriver`
    (the fused runner: the distributed stack's world, autopilots, sensors and plume in one
    process, the same bits).

    Each vehicle is armed on the ground at its start and takes off to the start altitude;
    once all hover within ``altitude_tolerance_m`` of it in hold mode — and not before sim
    time ``start_s`` — all switch to offboard and their behaviours fly the episode. Every
    command is recorded at its tick boundary (:attr:`commands`). The flight modes and the
    behaviours' declarations are read off the autopilots, which the in-process driver holds."""

    takeoff_timeout_s = 60.0
    altitude_tolerance_m = 0.03

    def __init__(self, scenario: Scenario, on_states: StatesObserver | None = None) -> None:
        self.scenario = scenario
        self.driver = InProcessDriver(on_states)
        self.driver.start(scenario)
        self.control_dt_s = 1.0 / scenario.time.control_hz
        self.commands: Boundary = {}
        self.autopilots = [f.autopilot for f in self.driver.runner.flights.values()]

    def give(self, command: Command) -> None:
        """``command`` to every vehicle at the driver's tick; it must be accepted."""
        batch = [(vid, command) for vid in self.driver.states()]
        for (vid, _), reply in zip(batch, self.driver.command(batch), strict=True):
            if not reply.accepted:
                raise RuntimeError(f"{vid}: {type(command).__name__}: {reply.reason}")
        self.commands.setdefault(self.driver.tick, []).extend(batch)

    def _hovering(self, altitude_m: float) -> bool:
        return all(ap.modes.mode == FlightMode.HOLD for ap in self.autopilots) and all(
            abs(s.position_enu_m[2] - altitude_m) <= self.altitude_tolerance_m
            for s in self.driver.states().values()
        )

    def take_off(self, altitude_m: float, start_s: float) -> None:
        """Arm, take off, hover till ``start_s``, then offboard: the behaviours fly from the
        next tick on."""
        drv = self.driver
        self.give(Arm())
        self.give(Takeoff(altitude_m=altitude_m))
        deadline = round(self.takeoff_timeout_s / self.control_dt_s)
        while not self._hovering(altitude_m):
            if drv.tick > deadline:
                raise RuntimeError(
                    f"vehicles not hovering at {altitude_m} m after {self.takeoff_timeout_s} s"
                )
            drv.step(1)
        drv.step(max(0, round(start_s / self.control_dt_s) - 1 - drv.tick))
        self.give(SetMode(mode=FlightMode.OFFBOARD))

    def observe(self, tally: Tally) -> None:
        """This tick's positions to ``tally``."""
        states = list(self.driver.states().values())
        tally.observe(states[0].sim_time_s, [s.position_enu_m for s in states])

    def close(self) -> None:
        self.driver.close()


def fused_episode(
    spec: EpisodeSpec,
    environment: Scenario | None = None,
    on_states: StatesObserver | None = None,
) -> tuple[Outcome, Schedule]:
    """The episode with the real vehicles, driven in process; its outcome and schedule
    (``on_states`` sees every tick's states from tick 0)."""
    scenario = episode_scenario(spec, environment)
    episode = FusedEpisode(scenario, on_states)
    try:
        episode.take_off(START_ALTITUDE_M, start_s(scenario, start_distances_m(spec)))
        drv = episode.driver
        drv.step(1)  # the first tick the behaviours fly
        t0 = next(iter(drv.states().values())).sim_time_s
        tally = _tally(spec, scenario, episode.control_dt_s, t0)
        episode.observe(tally)
        declared = _fly_fused(spec, episode, tally)
        elapsed_s = next(iter(drv.states().values())).sim_time_s - t0
        schedule = Schedule(scenario, episode.commands, drv.tick)
        return tally.outcome(elapsed_s, declared), schedule
    finally:
        episode.close()


def _fly_fused(spec: EpisodeSpec, episode: FusedEpisode, tally: Tally) -> SourceEstimate | None:
    """Step until a declaration or the time limit; every tick's positions and every new
    reading go to ``tally``."""
    drv = episode.driver
    behaviors = [ap.behavior for ap in episode.autopilots]
    seen = dict(drv.readings())
    for _ in range(round(spec.time_limit_s * episode.scenario.time.control_hz)):
        drv.step(1)
        episode.observe(tally)
        for vid, r in drv.readings().items():
            if seen.get(vid) is not r:
                seen[vid] = r
                tally.reading(r)
        declared = declaration_of(behaviors)
        if declared is not None:
            return declared
    return None
