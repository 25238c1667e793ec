"""Where an environment's world runs: in this process (fused) or on the bus.

Both backends offer the same small surface: start a world for a scenario, hand commands to
autopilots (they take effect on the next tick), advance k control ticks, and read the agents'
latest states and readings.

- :class:`FusedBackend`: a :class:`~deploy.fused.FusedRunner` (no bus, no processes).
- :class:`BusBackend`: the distributed stack. Started by the backend (router, plume, physics and
  one autopilot process per ``vehicles_per_process`` vehicles, on a free loopback port; a new
  stack per episode, since the spawns change), it holds the lockstep's clock with a
  :class:`~deploy.envs.clock.ClockHolder` (a parked extra vehicle far from the others), so the
  stack gives the same states as the fused backend. Attached to a running stack
  (``attach=ENDPOINT``), it neither respawns nor holds the clock: the world runs at its own
  pace, a step waits until k more ticks were published, and runs do not repeat.
"""

from __future__ import annotations

import logging
import tempfile
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Protocol

import msgspec
import zenoh

from deploy.demo import command_reply
from deploy.envs.clock import ClockError, ClockHolder
from deploy.fused import FusedRunner
from deploy.launcher import Launcher, LaunchOptions
from deploy.scaling import write_scenario
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import (
    Command,
    CommandReply,
    ConcentrationReading,
    SimTick,
    VehicleState,
)
from swarmbus.scenario import Scenario, Vehicle
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from swarmbus.vehicle_types import load_vehicle_type

log = logging.getLogger(__name__)

CLOCK_VEHICLE = "env-clock"
CLOCK_OFFSET_M = 400.0  # the clock's parked vehicle: this far upwind of the vehicles' box
COMMAND_TIMEOUT_S = 5.0
BUS_ROLES = ("router", "plume", "physics", "autopilot")


class BackendError(RuntimeError):
    pass


class Backend(Protocol):
    def start(self, scenario: Scenario) -> None:
        """A world at tick 0 for ``scenario`` (the previous one, if any, is gone)."""

    def command(self, commands: Sequence[tuple[str, Command]]) -> list[CommandReply]:
        """Hand each command to its vehicle's autopilot; the replies in the same order."""

    def step(self, ticks: int) -> None:
        """Advance ``ticks`` control ticks."""

    @property
    def tick(self) -> int: ...

    def states(self) -> dict[str, VehicleState]:
        """The agents' states of the current tick."""

    def readings(self) -> dict[str, ConcentrationReading]:
        """Each agent's latest reading (none before its first)."""

    def close(self) -> None: ...


class FusedBackend:
    def __init__(self) -> None:
        self._runner: FusedRunner | None = None

    @property
    def runner(self) -> FusedRunner:
        if self._runner is None:
            raise BackendError("the environment has no world before reset()")
        return self._runner

    def start(self, scenario: Scenario) -> None:
        self.close()
        self._runner = FusedRunner(scenario)

    def command(self, commands: Sequence[tuple[str, Command]]) -> list[CommandReply]:
        runner = self.runner
        return [runner.command(vid, cmd) for vid, cmd in commands]

    def step(self, ticks: int) -> None:
        self.runner.step(ticks)

    @property
    def tick(self) -> int:
        return self.runner.tick

    def states(self) -> dict[str, VehicleState]:
        return {s.vehicle_id: s for s in self.runner.states}

    def readings(self) -> dict[str, ConcentrationReading]:
        return self.runner.latest_readings

    def close(self) -> None:
        if self._runner is not None:
            self._runner.close()
            self._runner = None


class _Readings:
    """The newest reading of every vehicle, from ``vehicle/*/concentration``."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self.latest: dict[str, ConcentrationReading] = {}
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(keys.all_vehicle_concentration(), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        try:
            vid = self.keys.vehicle_id_of(str(sample.key_expr))
            reading = decode(sample.payload.to_bytes(), ConcentrationReading)
        except (KeyNameError, MessageError):
            return
        with self._lock:
            self.latest[vid] = reading

    def snapshot(self) -> dict[str, ConcentrationReading]:
        with self._lock:
            return dict(self.latest)

    def close(self) -> None:
        self._sub.undeclare()


class _Ticks:
    """The newest ``sim/tick`` (attached mode: the world runs on its own)."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.latest: SimTick | None = None
        self._cond = threading.Condition()
        self._sub = session.declare_subscriber(keys.tick(), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        try:
            tick = decode(sample.payload.to_bytes(), SimTick)
        except MessageError:
            return
        with self._cond:
            if self.latest is None or tick.tick > self.latest.tick:
                self.latest = tick
                self._cond.notify_all()

    def wait_past(self, tick: int, timeout_s: float) -> SimTick:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while self.latest is None or self.latest.tick < tick:
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    raise BackendError(f"no tick {tick} on the bus within {timeout_s:.0f} s")
                self._cond.wait(remaining)
            return self.latest

    def close(self) -> None:
        self._sub.undeclare()


def with_clock_vehicle(scenario: Scenario) -> Scenario:
    """``scenario`` plus the clock holder's parked vehicle, upwind of every other vehicle."""
    xs = [v.spawn_enu_m[0] for v in scenario.vehicles]
    ys = [v.spawn_enu_m[1] for v in scenario.vehicles]
    parked = Vehicle(
        id=CLOCK_VEHICLE,
        spawn_enu_m=(min(xs) - CLOCK_OFFSET_M, sum(ys) / len(ys), 0.0),
    )
    return msgspec.structs.replace(scenario, vehicles=[*scenario.vehicles, parked])


class BusBackend:
    """The distributed stack (see the module doc); ``attach``: a running stack's router."""

    def __init__(
        self,
        attach: str | None = None,
        vehicles_per_process: int = 1,
        run_dir: Path | None = None,
        startup_timeout_s: float = 120.0,
    ) -> None:
        self.attach = attach
        self.vehicles_per_process = vehicles_per_process
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self.run_dir = run_dir
        self.startup_timeout_s = startup_timeout_s
        self._launcher: Launcher | None = None
        self._session: zenoh.Session | None = None
        self._holder: ClockHolder | None = None
        self._ticks: _Ticks | None = None
        self._readings: _Readings | None = None
        self._keys = Keys()
        self._agents: tuple[str, ...] = ()
        self._tick = 0
        self._states: dict[str, VehicleState] = {}

    # ------------------------------------------------------------------ lifecycle
    def start(self, scenario: Scenario) -> None:
        self._agents = tuple(v.id for v in scenario.vehicles)
        self._keys = Keys(scenario.world.name)
        if self.attach is not None:
            self._attach(scenario)
        else:
            self._launch(scenario)

    def _attach(self, scenario: Scenario) -> None:
        if self._session is None:
            net = NetworkConfig(connect=[self.attach or ""], listen=[])
            self._session = open_session(net)
            self._ticks = _Ticks(self._session, self._keys)
            self._readings = _Readings(self._session, self._keys)
        assert self._ticks is not None
        latest = self._ticks.wait_past(0, self.startup_timeout_s)
        self._take(latest.tick, latest.states)

    def _launch(self, scenario: Scenario) -> None:
        self.close()
        if self.run_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="plumeswarm-env-")
        run_dir = self.run_dir or Path(self._tmp.name if self._tmp else ".")
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        sc = with_clock_vehicle(scenario)
        sc = msgspec.structs.replace(
            sc,
            network=msgspec.structs.replace(sc.network, connect=[endpoint]),
            time=msgspec.structs.replace(
                sc.time,
                mode="lockstep",
                duration_s=0.0,
                startup_timeout_s=max(sc.time.startup_timeout_s, self.startup_timeout_s),
            ),
        )
        path = write_scenario(sc, run_dir / "scenario.toml")
        opts = LaunchOptions(
            scenario_path=path,
            headless=True,
            run_dir=run_dir,
            roles=BUS_ROLES,
            vehicles=self._agents,
            vehicles_per_process=self.vehicles_per_process,
            verbose=0,
        )
        rotors = len(load_vehicle_type(sc.vehicle(CLOCK_VEHICLE).type).rotors)
        launcher = self._launcher = Launcher(sc, opts)

        def on_bus(session: zenoh.Session) -> None:
            self._holder = ClockHolder(session, self._keys, CLOCK_VEHICLE, self._agents, rotors)
            self._readings = _Readings(session, self._keys)

        launcher.start(on_bus)
        self._session = launcher.session
        self._tick = 0
        self._hold(0)

    def close(self) -> None:
        for part in (self._holder, self._readings, self._ticks):
            if part is not None:
                part.close()
        self._holder = self._readings = self._ticks = None
        if self._launcher is not None:
            self._launcher.stop()
            self._launcher = None
        elif self._session is not None:
            self._session.close()
        self._session = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    # ------------------------------------------------------------------ stepping
    def _take(self, tick: int, states: Sequence[VehicleState]) -> None:
        self._tick = tick
        agents = set(self._agents)
        self._states = {s.vehicle_id: s for s in states if s.vehicle_id in agents}

    def _hold(self, tick: int) -> None:
        assert self._holder is not None
        try:
            states = self._holder.wait_answered(tick, self.startup_timeout_s)
        except ClockError as exc:
            raise BackendError(str(exc)) from None
        self._take(tick, states)

    def step(self, ticks: int) -> None:
        if self._holder is not None:
            for _ in range(ticks):
                self._holder.release(self._tick)
                self._hold(self._tick + 1)
            return
        if self._ticks is None:
            raise BackendError("the environment has no world before reset()")
        latest = self._ticks.wait_past(self._tick + ticks, self.startup_timeout_s)
        self._take(latest.tick, latest.states)

    @property
    def tick(self) -> int:
        return self._tick

    def states(self) -> dict[str, VehicleState]:
        return self._states

    def readings(self) -> dict[str, ConcentrationReading]:
        return self._readings.snapshot() if self._readings is not None else {}

    def command(self, commands: Sequence[tuple[str, Command]]) -> list[CommandReply]:
        """All queries first, then all replies: one round trip for the lot, not one each."""
        session = self._session
        if session is None:
            raise BackendError("the environment has no world before reset()")
        pending: list[tuple[str, Any]] = [
            (
                vid,
                session.get(
                    self._keys.vehicle_cmd(vid), payload=encode(cmd), timeout=COMMAND_TIMEOUT_S
                ),
            )
            for vid, cmd in commands
        ]
        return [_reply_of(vid, replies) for vid, replies in pending]


def _reply_of(vehicle_id: str, replies: Any) -> CommandReply:
    reply = command_reply(vehicle_id, replies)
    if reply is None:
        reason = f"no autopilot answered within {COMMAND_TIMEOUT_S:.0f} s"
        return CommandReply(vehicle_id=vehicle_id, accepted=False, reason=reason)
    return reply
