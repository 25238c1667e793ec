"""The PettingZoo ``ParallelEnv``: one agent per vehicle, searching for the plume's source.

An episode: ``reset(seed=…)`` spawns every vehicle on the ground at a random point of the
scenario's ``[env]`` box, takes each off to its random altitude from that box, and switches it
to offboard mode; from then on each agent's action is an ENU velocity setpoint and a yaw rate,
flown by the vehicle's own autopilot, and every ``step`` advances ``ticks_per_step`` control
ticks. Units, frames, spaces and the reward are in docs/envs.md.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import gymnasium
import msgspec
import numpy as np
import numpy.typing as npt
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from agents.anemometer import Anemometer
from deploy.scaling import multirotors_only, scale_scenario, scenario_toml
from plume_atmosphere.wind import wind_from_scenario
from plumeswarm.envs.render import Renderer
from plumeswarm.experiments.driver import DRIVERS, BusDriver, Driver, DriverError, open_driver
from swarmbus.messages import (
    Arm,
    Command,
    ConcentrationReading,
    FlightMode,
    Hold,
    SetMode,
    Setpoint,
    Takeoff,
    VehicleState,
)
from swarmbus.scenario import Scenario, load_scenario, parse_scenario, resolve_scenario_path

Obs = npt.NDArray[np.float32]
Action = npt.NDArray[np.float32]

TAKEOFF_CHECK_TICKS = 12  # the take-off is checked every this many ticks (both backends alike)
TAKEOFF_TOLERANCE_M = 0.5
TAKEOFF_TIMEOUT_S = 40.0
MIN_SPAWN_SEPARATION_M = 2.0
SPAWN_TRIES = 10_000
SUCCESS_REWARD = 10.0
FAILURE_REWARD = -10.0
RENDER_MODES = ["human", "rgb_array"]
OBS_LIMIT = 1e5  # the observation box's bounds (every entry is far inside them)
SELF_FEATURES = 10  # position 3, velocity 3, wind 3, reading 1
PEER_FEATURES = 5  # relative position 3, reading 1, present 1


@dataclass(frozen=True)
class AgentStep:
    """What the reward and termination callables see of one agent after a step."""

    vehicle_id: str
    state: VehicleState
    reading: ConcentrationReading | None
    distance_m: float  # to the nearest source's release point
    previous_distance_m: float
    elapsed_s: float  # sim time since the episode's start (offboard)
    time_limit_s: float
    success_radius_m: float
    outside_geofence: bool


RewardFn = Callable[[AgentStep], float]
TerminationFn = Callable[[AgentStep], tuple[bool, bool]]


def default_termination(step: AgentStep) -> tuple[bool, bool]:
    """(terminated, truncated): found the source, crashed or left the geofence; time's up."""
    terminated = (
        step.distance_m <= step.success_radius_m or step.state.crashed or step.outside_geofence
    )
    return terminated, (not terminated and step.elapsed_s >= step.time_limit_s)


def default_reward(step: AgentStep) -> float:
    """Metres of progress toward the source; +10 on success, −10 on a crash or a fence exit."""
    reward = step.previous_distance_m - step.distance_m
    if step.distance_m <= step.success_radius_m:
        reward += SUCCESS_REWARD
    if step.state.crashed or step.outside_geofence:
        reward += FAILURE_REWARD
    return reward


def yaw_deg_of(q: tuple[float, float, float, float]) -> float:
    x, y, z, w = q
    return math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def wrap_deg(angle: float) -> float:
    return (angle + 180.0) % 360.0 - 180.0


def env_scenario(scenario: Scenario | str | Path | None, overrides: Sequence[str] = ()) -> Scenario:
    """A scenario, or one loaded from a path or a bundled name (None: the default), with
    ``section.key=value`` overrides (as ``plumeswarm --set``); a bad one raises
    :class:`~swarmbus.scenario.ScenarioError` (a ``ValueError``), one line naming the key."""
    if isinstance(scenario, Scenario):
        if not overrides:
            return scenario
        return parse_scenario(scenario_toml(scenario), "scenario", overrides)
    path = resolve_scenario_path(None if scenario is None else str(scenario))
    return load_scenario(path, overrides)


def make_driver(backend: str | Driver, attach: str | None) -> Driver:
    """``backend``: ``"fused"``, ``"bus"`` or a :class:`~plumeswarm.experiments.driver.Driver` of
    one's own."""
    if not isinstance(backend, str):
        return backend
    if backend not in DRIVERS:
        raise ValueError(f"backend: expected 'fused' or 'bus', got {backend!r}")
    return open_driver(backend, attach=attach)


class PlumeSwarmEnv(ParallelEnv[str, Obs, Action]):  # type: ignore[misc]
    """One agent per vehicle of the scenario (or of its copy scaled to ``vehicles``)."""

    metadata: ClassVar[dict[str, Any]] = {
        "name": "plumeswarm_v0",
        "render_modes": RENDER_MODES,
        "render_fps": 10,
    }

    def __init__(
        self,
        scenario: Scenario | str | Path | None = None,
        *,
        scenario_overrides: Sequence[str] = (),
        vehicles: int | None = None,
        backend: str | Driver = "fused",
        attach: str | None = None,
        ticks_per_step: int = 12,
        k_peers: int = 2,
        max_speed_xy_m_s: float = 5.0,
        max_speed_z_m_s: float = 2.0,
        max_yaw_rate_deg_s: float = 90.0,
        reward_fn: RewardFn = default_reward,
        termination_fn: TerminationFn = default_termination,
        render_mode: str | None = None,
    ) -> None:
        base = env_scenario(scenario, scenario_overrides)
        if vehicles is not None:
            base = scale_scenario(base, vehicles)
        multirotors_only(base, "the environments fly every vehicle on velocity setpoints")
        self.scenario = msgspec.structs.replace(
            base,
            vehicles=[msgspec.structs.replace(v, mission=[], behavior=None) for v in base.vehicles],
        )
        self.control_dt_s = 1.0 / self.scenario.time.control_hz
        _check_positive("ticks_per_step", ticks_per_step)
        timeouts = [self.scenario.failsafe_for(v.id).offboard_timeout_s for v in base.vehicles]
        if ticks_per_step * self.control_dt_s > min(timeouts):
            raise ValueError(
                f"ticks_per_step: {ticks_per_step} ticks ({ticks_per_step * self.control_dt_s} s) "
                f"exceed the offboard timeout ({min(timeouts)} s): the autopilot would leave "
                "offboard between two steps"
            )
        if k_peers < 0:
            raise ValueError(f"k_peers: must be >= 0, got {k_peers}")
        for name, value in (
            ("max_speed_xy_m_s", max_speed_xy_m_s),
            ("max_speed_z_m_s", max_speed_z_m_s),
            ("max_yaw_rate_deg_s", max_yaw_rate_deg_s),
        ):
            _check_positive(name, value)
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise ValueError(f"render_mode: expected human or rgb_array, got {render_mode!r}")
        self.ticks_per_step = ticks_per_step
        self.k_peers = k_peers
        self.action_scale = np.array(
            [max_speed_xy_m_s, max_speed_xy_m_s, max_speed_z_m_s, max_yaw_rate_deg_s]
        )
        self.reward_fn = reward_fn
        self.termination_fn = termination_fn
        self.render_mode = render_mode
        self.backend = make_driver(backend, attach)
        self.possible_agents = [v.id for v in self.scenario.vehicles]
        self.agents: list[str] = []
        # Each vehicle's anemometer, as its autopilot and its behaviours read it: the scenario's
        # wind at the vehicle's position and sim time, plus the anemometer's seeded noise.
        wind = wind_from_scenario(self.scenario)
        seed = self.scenario.world.seed
        self.anemometers = {
            v.id: Anemometer(self.scenario.anemometer, wind, seed, k)
            for k, v in enumerate(self.scenario.vehicles)
        }
        self.sources_enu_m = np.array(
            [(s.x_m, s.y_m, s.release_height_m) for s in self.scenario.plume.sources]
        )
        self._np_random: np.random.Generator | None = None
        self._yaw_deg: dict[str, float] = {}
        self._distance: dict[str, float] = {}
        self._home: dict[str, tuple[float, float, float]] = {}
        self._last_detection_s: dict[str, float] = {}
        self._start_s = 0.0
        self._renderer: Renderer | None = None

    # ------------------------------------------------------------------ spaces
    @property
    def observation_size(self) -> int:
        return SELF_FEATURES + PEER_FEATURES * self.k_peers + 1

    @functools.cache  # noqa: B019 - one space object per agent, as the API asks
    def observation_space(self, agent: str) -> gymnasium.spaces.Box:
        return gymnasium.spaces.Box(
            -OBS_LIMIT, OBS_LIMIT, shape=(self.observation_size,), dtype=np.float32
        )

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> gymnasium.spaces.Box:
        return gymnasium.spaces.Box(-1.0, 1.0, shape=(4,), dtype=np.float32)

    # ------------------------------------------------------------------ episode
    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Obs], dict[str, dict[str, Any]]]:
        if seed is not None or self._np_random is None:
            self._np_random, _ = seeding.np_random(seed)
        rng = self._np_random
        episode = self._episode_scenario(rng)
        backend = self.backend
        backend.start(episode)
        states = backend.states()
        self.agents = list(self.possible_agents)
        altitudes = {
            v.id: float(rng.uniform(episode.env.start_min_enu_m[2], episode.env.start_max_enu_m[2]))
            for v in episode.vehicles
        }
        self._home = {vid: s.position_enu_m for vid, s in states.items()}
        commands: list[tuple[str, Command]] = []
        for vid in self.agents:
            commands += [(vid, Arm()), (vid, Takeoff(altitude_m=altitudes[vid]))]
        self._command(commands, strict=self.backend_respawns)
        targets = {vid: self._home[vid][2] + altitudes[vid] for vid in self.agents}
        self._take_off(targets)
        states = backend.states()
        self._yaw_deg = {vid: yaw_deg_of(states[vid].attitude_xyzw) for vid in self.agents}
        commands = []
        for vid in self.agents:
            hover = Setpoint(velocity_enu_m_s=(0.0, 0.0, 0.0), yaw_deg=self._yaw_deg[vid])
            commands += [(vid, hover), (vid, SetMode(mode=FlightMode.OFFBOARD))]
        self._command(commands, strict=True)
        self._start_s = states[self.agents[0]].sim_time_s
        self._last_detection_s = {}
        self._distance = {vid: self._source_distance(states[vid]) for vid in self.agents}
        observations = self._observations(states, backend.readings())
        infos = {vid: self._info(states[vid], False) for vid in self.agents}
        if self.render_mode == "human":
            self.render()
        return observations, infos

    @property
    def backend_respawns(self) -> bool:
        """False for a stack this environment attached to (its vehicles may already fly)."""
        return not (isinstance(self.backend, BusDriver) and self.backend.attach is not None)

    def _episode_scenario(self, rng: np.random.Generator) -> Scenario:
        env = self.scenario.env
        lo = np.array(env.start_min_enu_m[:2])
        hi = np.array(env.start_max_enu_m[:2])
        spawns: list[npt.NDArray[np.float64]] = []
        for _ in self.scenario.vehicles:
            for _ in range(SPAWN_TRIES):
                xy = rng.uniform(lo, hi)
                if all(np.hypot(*(xy - other)) >= MIN_SPAWN_SEPARATION_M for other in spawns):
                    break
            else:
                raise ValueError(
                    f"env.start_min_enu_m/start_max_enu_m: no room for {len(spawns) + 1} "
                    f"vehicles {MIN_SPAWN_SEPARATION_M} m apart in the box {lo}..{hi}"
                )
            spawns.append(xy)
        vehicles = [
            msgspec.structs.replace(v, spawn_enu_m=(float(xy[0]), float(xy[1]), 0.0))
            for v, xy in zip(self.scenario.vehicles, spawns, strict=True)
        ]
        return msgspec.structs.replace(self.scenario, vehicles=vehicles)

    def _command(self, commands: list[tuple[str, Command]], strict: bool) -> None:
        for (vid, cmd), reply in zip(commands, self.backend.command(commands), strict=True):
            if strict and not reply.accepted:
                raise DriverError(f"{vid} refused {type(cmd).__name__}: {reply.reason}")

    def _take_off(self, targets: dict[str, float]) -> None:
        backend = self.backend
        deadline_tick = backend.tick + round(TAKEOFF_TIMEOUT_S / self.control_dt_s)
        while True:
            states = backend.states()
            if all(
                abs(states[v].position_enu_m[2] - z) < TAKEOFF_TOLERANCE_M
                and abs(states[v].velocity_enu_m_s[2]) < TAKEOFF_TOLERANCE_M
                for v, z in targets.items()
            ):
                return
            if backend.tick >= deadline_tick:
                low = [v for v, z in targets.items() if states[v].position_enu_m[2] < z - 1.0]
                raise DriverError(
                    f"take-off not done after {TAKEOFF_TIMEOUT_S:.0f} s sim: {', '.join(low)}"
                )
            backend.step(TAKEOFF_CHECK_TICKS)

    def step(
        self, actions: dict[str, Action]
    ) -> tuple[
        dict[str, Obs],
        dict[str, float],
        dict[str, bool],
        dict[str, bool],
        dict[str, dict[str, Any]],
    ]:
        step_s = self.ticks_per_step * self.control_dt_s
        commands: list[tuple[str, Command]] = []
        for vid in self.agents:
            action = np.clip(np.asarray(actions.get(vid, np.zeros(4)), dtype=np.float64), -1, 1)
            vx, vy, vz, yaw_rate = (action * self.action_scale).tolist()
            self._yaw_deg[vid] = wrap_deg(self._yaw_deg[vid] + yaw_rate * step_s)
            commands.append(
                (vid, Setpoint(velocity_enu_m_s=(vx, vy, vz), yaw_deg=self._yaw_deg[vid]))
            )
        self._command(commands, strict=False)  # a crashed vehicle refuses: its agent ends
        self.backend.step(self.ticks_per_step)
        states = self.backend.states()
        readings = self.backend.readings()
        observations = self._observations(states, readings)
        rewards: dict[str, float] = {}
        terminated: dict[str, bool] = {}
        truncated: dict[str, bool] = {}
        infos: dict[str, dict[str, Any]] = {}
        done: list[tuple[str, Command]] = []
        for vid in self.agents:
            state = states[vid]
            distance = self._source_distance(state)
            outcome = AgentStep(
                vehicle_id=vid,
                state=state,
                reading=readings.get(vid),
                distance_m=distance,
                previous_distance_m=self._distance[vid],
                elapsed_s=state.sim_time_s - self._start_s,
                time_limit_s=self.scenario.env.time_limit_s,
                success_radius_m=self.scenario.env.success_radius_m,
                outside_geofence=self._outside_geofence(vid, state),
            )
            self._distance[vid] = distance
            rewards[vid] = float(self.reward_fn(outcome))
            terminated[vid], truncated[vid] = self.termination_fn(outcome)
            infos[vid] = self._info(state, distance <= self.scenario.env.success_radius_m)
            if terminated[vid] or truncated[vid]:
                done.append((vid, Hold()))
        if done:
            self._command(done, strict=False)  # the vehicle holds where its episode ended
            ended = {vid for vid, _ in done}
            self.agents = [a for a in self.agents if a not in ended]
        if self.render_mode == "human":
            self.render()
        return observations, rewards, terminated, truncated, infos

    # ------------------------------------------------------------------ observations
    def _source_distance(self, state: VehicleState) -> float:
        offsets = self.sources_enu_m - np.asarray(state.position_enu_m)
        return float(np.min(np.linalg.norm(offsets, axis=1)))

    def _outside_geofence(self, vid: str, state: VehicleState) -> bool:
        fence = self.scenario.failsafe_for(vid)
        hx, hy, hz = self._home[vid]
        x, y, z = state.position_enu_m
        return bool(
            math.hypot(x - hx, y - hy) > fence.geofence_max_distance_m
            or z - hz > fence.geofence_max_altitude_m
        )

    def _info(self, state: VehicleState, success: bool) -> dict[str, Any]:
        return {
            "sim_time_s": state.sim_time_s,
            "distance_m": self._distance.get(state.vehicle_id, math.nan),
            "success": success,
            "crashed": state.crashed,
        }

    def _observations(
        self, states: dict[str, VehicleState], readings: dict[str, ConcentrationReading]
    ) -> dict[str, Obs]:
        ids = self.possible_agents
        positions = np.array([states[v].position_enu_m for v in ids])
        values = np.array([_value(readings.get(v)) for v in ids])
        for vid in ids:
            r = readings.get(vid)
            if r is not None and (r.reported_g_m3 or 0.0) > 0.0:
                self._last_detection_s[vid] = r.sim_time_s
        out: dict[str, Obs] = {}
        for i, vid in enumerate(ids):
            if vid not in self.agents:
                continue
            state = states[vid]
            obs = np.zeros(self.observation_size, dtype=np.float64)
            obs[0:3] = state.position_enu_m
            obs[3:6] = state.velocity_enu_m_s
            wind = self.anemometers[vid].read(
                vid, state.tick, state.sim_time_s, state.position_enu_m
            )
            obs[6:9] = wind.wind_enu_m_s
            obs[9] = values[i]
            if self.k_peers and len(ids) > 1:
                rel = np.delete(positions, i, axis=0) - positions[i]
                peer_values = np.delete(values, i)
                order = np.argsort(np.linalg.norm(rel, axis=1), kind="stable")[: self.k_peers]
                for slot, j in enumerate(order):
                    base = SELF_FEATURES + PEER_FEATURES * slot
                    obs[base : base + 3] = rel[j]
                    obs[base + 3] = peer_values[j]
                    obs[base + 4] = 1.0
            since = self._last_detection_s.get(vid, self._start_s)
            obs[-1] = max(0.0, state.sim_time_s - since)
            out[vid] = np.clip(obs, -OBS_LIMIT, OBS_LIMIT).astype(np.float32)
        return out

    # ------------------------------------------------------------------ render, close
    def render(self) -> npt.NDArray[np.uint8] | None:
        if self.render_mode is None:
            gymnasium.logger.warn("render() without a render_mode: nothing to draw")
            return None
        if self._renderer is None:
            self._renderer = Renderer(self.scenario, self.render_mode)
        return self._renderer.draw(self.backend.states(), self.backend.readings())

    @property
    def viewer_url(self) -> str | None:
        """The meshcat page that ``render_mode="human"`` serves on 127.0.0.1 (None before the
        first render, and in the other modes)."""
        return self._renderer.web_url if self._renderer is not None else None

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
        self.backend.close()


def _value(reading: ConcentrationReading | None) -> float:
    if reading is None or reading.reported_g_m3 is None:
        return 0.0
    return reading.reported_g_m3


def _check_positive(name: str, value: float) -> None:
    if not value > 0:
        raise ValueError(f"{name}: must be > 0, got {value!r}")
