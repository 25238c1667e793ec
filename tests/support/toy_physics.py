"""A small rigid-body multirotor written for the agents' tests, independent of sim_world.

It follows the agreed actuator convention (docs/physics.md): u → target ω = u·ω_max,
first-order motor lag, thrust k_f·ω² along body +z at the rotor, reaction torque −spin·k_m·ω²
about body z; linear body-axis drag against the air velocity; flat ground at z = 0. It lets the
pure autopilot logic be flown closed-loop without the physics process.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from swarmbus.messages import ConcentrationReading, VehicleState
from swarmbus.vehicle_types import VehicleType

if TYPE_CHECKING:
    import zenoh

    from agents.autopilot import Autopilot
    from swarmbus.scenario import Scenario

G = 9.80665


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ]
    )


class ToyVehicle:
    def __init__(
        self,
        vt: VehicleType,
        vehicle_id: str = "v",
        position: tuple[float, float, float] = (0.0, 0.0, 0.0),
        yaw_deg: float = 0.0,
        wind: tuple[float, float, float] = (0.0, 0.0, 0.0),
        physics_hz: int = 240,
    ) -> None:
        self.vt = vt
        self.vehicle_id = vehicle_id
        self.dt = 1.0 / physics_hz
        self.p = np.array(position, dtype=float)
        self.v = np.zeros(3)
        half = math.radians(yaw_deg) / 2
        self.q = np.array([0.0, 0.0, math.sin(half), math.cos(half)])
        self.w = np.zeros(3)
        self.omega = np.zeros(len(vt.rotors))
        self.wind = np.array(wind, dtype=float)
        self.pos = np.array([r.position_m for r in vt.rotors])
        self.spin = np.array([r.spin for r in vt.rotors], dtype=float)
        self.inertia = np.array(vt.inertia_kg_m2)
        self.on_ground = self.p[2] <= 0.0
        self.crashed = False
        self.steps = 0

    def step(self, u: list[float], substeps: int = 2) -> None:
        vt = self.vt
        target = np.clip(np.asarray(u, dtype=float), 0, 1) * vt.max_rotor_speed_rad_s
        for _ in range(substeps):
            tau = vt.motor_time_constant_s
            alpha = 1.0 if tau <= 0 else 1 - math.exp(-self.dt / tau)
            self.omega += alpha * (target - self.omega)
            thrust = vt.thrust_coeff_n_per_rad2_s2 * self.omega**2
            forces_body = np.zeros((len(thrust), 3))
            forces_body[:, 2] = thrust
            torque = np.cross(self.pos, forces_body).sum(axis=0)
            torque[2] += np.sum(-self.spin * vt.torque_coeff_nm_per_rad2_s2 * self.omega**2)
            r = quat_to_matrix(self.q)
            air_body = r.T @ (self.v - self.wind)
            drag_body = -np.array(vt.linear_drag_n_per_m_s) * air_body
            f_world = r @ (np.array([0, 0, thrust.sum()]) + drag_body) - np.array(
                [0, 0, vt.mass_kg * G]
            )
            acc = f_world / vt.mass_kg
            self.v += acc * self.dt
            self.p += self.v * self.dt
            wdot = (torque - np.cross(self.w, self.inertia * self.w)) / self.inertia
            self.w += wdot * self.dt
            dq = quat_mul(self.q, np.array([*(0.5 * self.w * self.dt), 0.0]))
            self.q = self.q + dq
            self.q /= np.linalg.norm(self.q)
            if self.p[2] <= 0.0:
                if self.v[2] < -vt.collision_half_extents_m[2] * 50:  # > 3 m/s into the ground
                    self.crashed = True
                self.p[2] = 0.0
                self.v[2] = max(self.v[2], 0.0)
                self.v[:2] *= 0.5  # friction
                if thrust.sum() < vt.mass_kg * G:  # resting: the ground levels the vehicle
                    yaw = math.atan2(
                        2 * (self.q[3] * self.q[2] + self.q[0] * self.q[1]),
                        1 - 2 * (self.q[1] ** 2 + self.q[2] ** 2),
                    )
                    self.q = np.array([0, 0, math.sin(yaw / 2), math.cos(yaw / 2)])
                    self.w[:] = 0.0
            self.on_ground = bool(self.p[2] < 0.02)
            self.steps += 1

    def state(self, tick: int, sim_time_s: float) -> VehicleState:
        return VehicleState(
            vehicle_id=self.vehicle_id,
            tick=tick,
            sim_time_s=sim_time_s,
            position_enu_m=(float(self.p[0]), float(self.p[1]), float(self.p[2])),
            velocity_enu_m_s=(float(self.v[0]), float(self.v[1]), float(self.v[2])),
            attitude_xyzw=(float(self.q[0]), float(self.q[1]), float(self.q[2]), float(self.q[3])),
            body_rates_rad_s=(float(self.w[0]), float(self.w[1]), float(self.w[2])),
            lat_deg=47.0,
            lon_deg=8.0,
            alt_m=488.0 + float(self.p[2]),
            on_ground=bool(self.on_ground),
            crashed=self.crashed,
        )


def toy_vehicles(scenario: Scenario, types: dict[str, VehicleType]) -> dict[str, ToyVehicle]:
    """The vehicles of ``types`` (id → type) at their spawn points, in the scenario's wind."""
    speed = scenario.wind.speed_m_s
    toward = math.radians(270.0 - scenario.wind.from_deg)  # ENU angle the air moves to
    wind = (speed * math.cos(toward), speed * math.sin(toward), 0.0)
    return {
        v.id: ToyVehicle(
            types[v.id], v.id, v.spawn_enu_m, v.spawn_yaw_deg, wind, scenario.time.physics_hz
        )
        for v in scenario.vehicles
        if v.id in types
    }


class ToyWorld:
    """Lockstep loop of autopilots against toy vehicles, ticking like the physics would."""

    def __init__(
        self,
        scenario: Scenario,
        autopilots: dict[str, Autopilot],
        field: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> None:
        from agents.sensor import ConcentrationSensor

        self.field = field
        self.sensors = {
            v.id: ConcentrationSensor.for_vehicle(scenario, i)
            for i, v in enumerate(scenario.vehicles)
        }
        self.readings: dict[str, list[ConcentrationReading]] = {v: [] for v in autopilots}
        self.scenario = scenario
        self.autopilots = autopilots
        self.vehicles = toy_vehicles(
            scenario, {vid: ap.vehicle_type for vid, ap in autopilots.items()}
        )
        self.tick = 0
        self.dt = 1.0 / scenario.time.control_hz

    @property
    def sim_time_s(self) -> float:
        return self.tick * self.dt

    def states(self) -> dict[str, VehicleState]:
        return {vid: toy.state(self.tick, self.sim_time_s) for vid, toy in self.vehicles.items()}

    def run(self, seconds: float, until: Callable[[], bool] | None = None) -> None:
        pending: dict[str, ConcentrationReading] = {}
        for _ in range(round(seconds / self.dt)):
            states = self.states()
            for vid, ap in self.autopilots.items():
                peers = [s for k, s in states.items() if k != vid]
                # like the node: the reading of the previous tick reaches this tick's step
                new = [pending.pop(vid)] if vid in pending else []
                self.readings[vid].extend(new)
                u = ap.step(states[vid], peers, new)
                self.vehicles[vid].step(u, self.scenario.substeps)
                if self.field is not None:
                    pos = states[vid].position_enu_m
                    true = float(self.field(np.array([pos]))[0])
                    pending[vid] = self.sensors[vid].reading(vid, self.sim_time_s, pos, true, [])
            self.tick += 1
            if until is not None and until():
                return


class BusToyPhysics:
    """A stand-in for the physics process on the bus, speaking the agreed lockstep protocol.

    Publishes ``SimTick`` k (and each ``VehicleState``), waits for every participant's
    ``ActuatorCommand`` for tick k (re-publishing tick 0 until all answered: the start
    handshake) and, with ``plume``, on a sensor tick (put on ``sim/sensor`` too) for the plume
    service's ``FieldSample`` of tick k, which goes into tick k + 1 (as the physics does); steps
    the toy vehicles, repeats. Without ``plume`` no tick waits for a plume (its readings are
    unavailable). Runs on its own thread until ``stop``.
    """

    def __init__(
        self,
        session: zenoh.Session,
        scenario: Scenario,
        participants: list[str] | None = None,
        timeout_s: float = 5.0,
        plume: bool = False,
    ) -> None:
        import threading

        from swarmbus.keys import Keys
        from swarmbus.vehicle_types import load_vehicle_type

        self.session = session
        self.scenario = scenario
        self.keys = Keys(scenario.world.name)
        self.participants = participants or [v.id for v in scenario.vehicles]
        self.timeout_s = timeout_s
        self.plume = plume
        self._sample: tuple[int, list[float] | None] | None = None  # the plume's: tick, values
        types = {v.id: load_vehicle_type(v.type) for v in scenario.vehicles}
        self.vehicles = toy_vehicles(scenario, types)
        self.dt = 1.0 / scenario.time.control_hz
        self.tick = 0
        self.error: str | None = None
        self._cond = threading.Condition()
        self._commands: dict[str, tuple[int, list[float]]] = {}
        self._stop = threading.Event()
        self._paused = threading.Event()  # no ticks while set (a cut link, seen from afar)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._subs = [
            session.declare_subscriber(self.keys.all_autopilot_actuators(), self._on_cmd),
            session.declare_subscriber(self.keys.plume_sample(), self._on_sample),
        ]
        self._pub = session.declare_publisher(self.keys.tick())
        self._sensor_pub = session.declare_publisher(self.keys.sensor_tick())
        self._state_pubs = {
            vid: session.declare_publisher(self.keys.vehicle_state(vid)) for vid in self.vehicles
        }

    def _on_cmd(self, sample: zenoh.Sample) -> None:
        from swarmbus.codec import decode
        from swarmbus.messages import ActuatorBatch

        msg = decode(sample.payload.to_bytes(), ActuatorBatch)
        with self._cond:
            for cmd in msg.commands:
                self._commands[cmd.vehicle_id] = (cmd.tick, list(cmd.rotor_commands))
            self._cond.notify_all()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        from swarmbus.codec import decode
        from swarmbus.messages import FieldSample

        msg = decode(sample.payload.to_bytes(), FieldSample)
        with self._cond:
            self._sample = (msg.tick, msg.values_g_m3)
            self._cond.notify_all()

    def start(self) -> BusToyPhysics:
        self._thread.start()
        return self

    def pause(self) -> None:
        """Publish no tick until :meth:`resume` (the world frozen where it is)."""
        self._paused.set()

    def resume(self) -> None:
        self._paused.clear()

    def _wait_while_paused(self) -> None:
        while self._paused.is_set() and not self._stop.wait(0.01):
            pass

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=10)
        for sub in self._subs:
            sub.undeclare()

    def __enter__(self) -> BusToyPhysics:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def sim_time_s(self) -> float:
        return self.tick * self.dt

    def _answered(self, k: int, queried: bool) -> bool:
        sampled = not queried or (self._sample is not None and self._sample[0] == k)
        return sampled and all(self._commands.get(v, (-1, []))[0] == k for v in self.participants)

    def _run(self) -> None:
        import time

        from swarmbus.codec import encode
        from swarmbus.messages import PlumeSample, SimTick

        period = self.scenario.sensor.resolved().period_ticks
        answer: PlumeSample | None = None
        while not self._stop.is_set():
            self._wait_while_paused()
            k = self.tick
            states = [toy.state(k, self.sim_time_s) for toy in self.vehicles.values()]
            queried = self.plume and k % period == 0
            tick = SimTick(
                tick=k,
                sim_time_s=self.sim_time_s,
                control_dt_s=self.dt,
                states=states,
                plume_queried=queried,
                plume_values=answer,
            )
            payload = encode(tick)
            for s in states:
                self._state_pubs[s.vehicle_id].put(encode(s))
            deadline = time.monotonic() + self.timeout_s
            self._pub.put(payload)
            if queried:
                self._sensor_pub.put(payload)
            republish = time.monotonic() + 0.05
            with self._cond:
                while not self._answered(k, queried):
                    if self._stop.is_set():
                        return
                    now = time.monotonic()
                    if now > deadline:
                        missing = [
                            v for v in self.participants if self._commands.get(v, (-1, []))[0] != k
                        ]
                        self.error = f"tick {k}: no actuators from {missing} (or no plume sample)"
                        return
                    if k == 0 and now > republish:  # start-up handshake
                        self._pub.put(payload)
                        if queried:
                            self._sensor_pub.put(payload)
                        republish = now + 0.05
                    self._cond.wait(0.05)
                commands = {v: self._commands[v][1] for v in self.participants}
                sampled = self._sample if queried else None
            answer = PlumeSample(tick=k, values_g_m3=sampled[1]) if sampled is not None else None
            for vid, toy in self.vehicles.items():
                toy.step(commands.get(vid, [0.0] * len(toy.vt.rotors)), self.scenario.substeps)
            self.tick += 1
