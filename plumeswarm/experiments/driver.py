"""One way to drive a world, wherever it runs: the :class:`Driver` protocol (start a world for a
scenario, hand commands to autopilots — they take effect on the next tick —, advance k control
ticks, read the vehicles' latest states and readings, close) and its two implementations,
chosen by :func:`open_driver` (docs/architecture.md, "Layers"). The environments, the
source-seeking benchmark, the demo and ``bench scale`` drive their worlds through it.

- :class:`InProcessDriver`: a :class:`~plumeswarm.experiments.fused.FusedRunner` (no bus, no
processes);
  its :attr:`~InProcessDriver.runner` also gives the world's autopilots, in this process.
- :class:`BusDriver`: the distributed stack. Started by the driver (router, plume, physics and
  one autopilot process per ``vehicles_per_process`` vehicles, on a free loopback port; a new
  stack per episode, since the spawns change) on the stepped clock (``time.mode = "stepped"``),
  which an :class:`agents.Swarm` client steps k ticks at a time: commands land on known ticks
  and the stack gives the same states as the in-process driver. Attached to a running stack
  (``attach=ENDPOINT``) it never respawns; it steps a stepped world's clock if it can have it,
  and otherwise lets the world run at its own pace (a step waits until k more ticks were
  published; such runs do not repeat). Started with ``follow=False`` it only commands the world
  it started, through its stack's own session (no subscriptions of its own once the world is at
  tick 0: no steps, states or readings): what ``bench scale`` measures the stack with.
"""

from __future__ import annotations

import logging
import tempfile
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Protocol

import zenoh

from agents import ClockError, Swarm
from deploy.launcher import Launcher, LaunchOptions
from deploy.scaling import local_stack_scenario
from plumeswarm.experiments.fused import FusedRunner, StatesObserver
from plumeswarm.experiments.launch import NODE_COMMAND
from swarmbus.codec import MessageError, decode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys
from swarmbus.messages import (
    Command,
    CommandReply,
    ConcentrationReading,
    SimTick,
    VehicleState,
)
from swarmbus.reqrep import ask, command_reply
from swarmbus.scenario import Scenario
from swarmbus.session import NetworkConfig

log = logging.getLogger(__name__)

COMMAND_TIMEOUT_S = 5.0
CLOCK_POLL_S = 0.02
ATTACH_TICK_S = 2.0  # a running world ticks within this; a paused stepped one publishes none
BUS_ROLES = ("router", "plume", "physics", "autopilot")


class DriverError(PlumeswarmError, RuntimeError):
    pass


class Driver(Protocol):
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


class InProcessDriver:
    """The world in this process; ``on_states`` sees every tick's states from tick 0."""

    def __init__(self, on_states: StatesObserver | None = None) -> None:
        self.on_states = on_states
        self._runner: FusedRunner | None = None

    @property
    def runner(self) -> FusedRunner:
        if self._runner is None:
            raise DriverError("the environment has no world before reset()")
        return self._runner

    def start(self, scenario: Scenario) -> None:
        self.close()
        self._runner = FusedRunner(scenario, on_states=self.on_states)

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
                    raise DriverError(f"no tick {tick} on the bus within {timeout_s:.0f} s")
                self._cond.wait(remaining)
            return self.latest

    def close(self) -> None:
        self._sub.undeclare()


class BusDriver:
    """The distributed stack (see the module doc). ``attach``: a running stack's router
    endpoint(s); otherwise the driver starts a stack of ``roles`` on this host for each world,
    its clock in ``mode`` (``"stepped"``: this driver holds it; ``"lockstep"`` or
    ``"realtime"``: the world runs on its own and a step waits for the ticks). ``on_join`` is
    called with the driver's :class:`~agents.Swarm` client before the world's first tick.
    ``follow=False``: once the world is at tick 0, the driver drops its client and its view of
    every state and only commands (see the module doc)."""

    def __init__(
        self,
        attach: str | Sequence[str] | None = None,
        vehicles_per_process: int = 1,
        run_dir: Path | None = None,
        startup_timeout_s: float = 120.0,
        *,
        mode: str = "stepped",
        roles: Sequence[str] = BUS_ROLES,
        record: bool = False,
        stand_ins: Mapping[str, str] | None = None,
        network: NetworkConfig | None = None,
        on_join: Callable[[Swarm], None] | None = None,
        follow: bool = True,
    ) -> None:
        if attach is not None and not follow:
            raise ValueError("follow=False: only for a stack the driver starts, not attach")
        self.attach = attach
        self.vehicles_per_process = vehicles_per_process
        self.run_dir = run_dir
        self.startup_timeout_s = startup_timeout_s
        self.mode = mode
        self.roles = tuple(roles)
        self.record = record
        self.stand_ins = dict(stand_ins or {})
        self.network = network
        self.on_join = on_join
        self.follow = follow
        self._tmp: tempfile.TemporaryDirectory[str] | None = None
        self._launcher: Launcher | None = None
        self._swarm: Swarm | None = None
        self._ticks: _Ticks | None = None
        self._keys = Keys()
        self._agents: tuple[str, ...] = ()
        self._stepped = False  # this driver holds a stepped world's clock
        self._tick = 0
        self._states: dict[str, VehicleState] = {}

    # ------------------------------------------------------------------ lifecycle
    @property
    def swarm(self) -> Swarm:
        """The driver's client of the world (commands, subscriptions, the clock)."""
        if self._swarm is None:
            raise DriverError("the driver has no world before start()")
        return self._swarm

    @property
    def launcher(self) -> Launcher | None:
        """The stack this driver started (None when attached)."""
        return self._launcher

    def supervise_once(self) -> None:
        """Restart what died in the stack this driver started (its supervisor's policy)."""
        if self._launcher is not None:
            self._launcher.supervise_once()

    def start(self, scenario: Scenario) -> None:
        self._agents = tuple(v.id for v in scenario.vehicles)
        self._keys = Keys(scenario.world.name)
        if self.attach is not None:
            self._attach(scenario)
        else:
            self._launch(scenario)

    def _join(self, world: str, endpoints: Sequence[str]) -> None:
        """Our client and tick subscriber, before the world publishes its first tick."""
        sw = self._swarm = Swarm.connect(
            world, list(endpoints), network=self.network, command_timeout_s=COMMAND_TIMEOUT_S
        )
        self._ticks = _Ticks(sw.session, self._keys)
        if self.on_join is not None:
            self.on_join(sw)

    def _attach(self, scenario: Scenario) -> None:
        if self._swarm is None:
            attach = self.attach or ""
            self._join(scenario.world.name, [attach] if isinstance(attach, str) else attach)
            self._stepped = True  # until the world says otherwise (first step)
        assert self._ticks is not None and self._swarm is not None
        self._wait_handshake()
        try:
            latest = self._ticks.wait_past(0, ATTACH_TICK_S)
        except DriverError:  # no tick: a stepped world paused before we joined
            clock = self._swarm.clock
            self._take(clock.tick if clock is not None else 0, [])
        else:
            self._take(latest.tick, latest.states)

    def _launch(self, scenario: Scenario) -> None:
        self.close()
        if self.run_dir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="plumeswarm-env-")
        run_dir = self.run_dir or Path(self._tmp.name if self._tmp else ".")
        sc, path = local_stack_scenario(scenario, run_dir, self.mode, self.startup_timeout_s)
        opts = LaunchOptions(
            node_command=NODE_COMMAND,
            scenario_path=path,
            headless=True,
            record=self.record,
            run_dir=run_dir,
            roles=self.roles,
            vehicles_per_process=self.vehicles_per_process,
            verbose=0,
            stand_ins=self.stand_ins,
        )
        launcher = self._launcher = Launcher(sc, opts)
        # The client joins once the router is up and before the physics starts: it sees tick 0.
        launcher.start(lambda _session: self._join(sc.world.name, sc.network.connect))
        self._stepped = self.mode == "stepped"
        assert self._ticks is not None and self._swarm is not None
        tick0 = self._ticks.wait_past(0, self.startup_timeout_s)
        self._wait_handshake()  # stepped: from then on the world is paused at tick 0
        self._take(tick0.tick, tick0.states)
        if not self.follow:
            self._unfollow()

    def _unfollow(self) -> None:
        """Only command from now on: no client, no tick subscriber, no launcher's view."""
        if self._ticks is not None:
            self._ticks.close()
            self._ticks = None
        if self._swarm is not None:
            self._swarm.close()
            self._swarm = None
        if self._launcher is not None:
            self._launcher.close_view()

    def _wait_handshake(self) -> None:
        """The physics publishes its clock once every autopilot answered the first tick (the
        start handshake): from then on the autopilots have a state and take commands."""
        assert self._swarm is not None
        deadline = time.monotonic() + self.startup_timeout_s
        while not _has_clock(self._swarm):
            if time.monotonic() > deadline:
                raise DriverError(
                    f"the world's start handshake did not finish in {self.startup_timeout_s} s"
                )
            time.sleep(CLOCK_POLL_S)

    def close(self) -> None:
        self._unfollow()  # our client before the router goes
        if self._launcher is not None:
            self._launcher.stop()
            self._launcher = None
        if self._tmp is not None:
            self._tmp.cleanup()
            self._tmp = None

    # ------------------------------------------------------------------ stepping
    def _take(self, tick: int, states: Sequence[VehicleState]) -> None:
        self._tick = tick
        agents = set(self._agents)
        self._states = {s.vehicle_id: s for s in states if s.vehicle_id in agents}

    def step(self, ticks: int) -> None:
        sw, seen = self._swarm, self._ticks
        if sw is None or seen is None:
            if self._launcher is not None and not self.follow:
                raise DriverError("a driver started with follow=False only commands")
            raise DriverError("the environment has no world before reset()")
        if self._stepped:
            try:
                reply = sw.step(ticks)
            except ClockError as exc:
                if self._launcher is not None or "stepped" not in str(exc):
                    raise DriverError(str(exc)) from None
                self._stepped = False  # an attached world that runs on its own
            else:
                tick = seen.wait_past(reply.tick, self.startup_timeout_s)
                self._take(tick.tick, tick.states)
                return
        latest = seen.wait_past(self._tick + ticks, self.startup_timeout_s)
        self._take(latest.tick, latest.states)

    @property
    def tick(self) -> int:
        return self._tick

    def states(self) -> dict[str, VehicleState]:
        return self._states

    def readings(self) -> dict[str, ConcentrationReading]:
        sw = self._swarm
        if sw is None:
            return {}
        latest = {vid: sw.reading(vid) for vid in self._agents}
        return {vid: r for vid, r in latest.items() if r is not None}

    def command(self, commands: Sequence[tuple[str, Command]]) -> list[CommandReply]:
        """All queries first, then all replies: one round trip for the lot, not one each."""
        if self._swarm is not None:
            session = self._swarm.session
        elif self._launcher is not None:
            session = self._launcher.session  # follow=False
        else:
            raise DriverError("the environment has no world before reset()")
        pending = [
            (vid, ask(session, self._keys.vehicle_cmd(vid), cmd, CommandReply, COMMAND_TIMEOUT_S))
            for vid, cmd in commands
        ]
        return [command_reply(vid, p.outcome()) for vid, p in pending]


DRIVERS = ("fused", "bus")


def open_driver(kind: str, attach: str | None = None, vehicles_per_process: int = 1) -> Driver:
    """The driver of ``kind``: ``"fused"`` (in this process) or ``"bus"`` (a stack this driver
    starts per world, or the running one at ``attach``)."""
    if kind == "fused":
        return InProcessDriver()
    if kind == "bus":
        return BusDriver(attach, vehicles_per_process)
    raise ValueError(f"driver: expected 'fused' or 'bus', got {kind!r}")


def _has_clock(sw: Swarm) -> bool:
    try:
        sw.sim_time  # noqa: B018 - raises until the physics published its clock
    except ClockError:
        return False
    return True
