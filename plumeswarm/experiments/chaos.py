"""``plumeswarm chaos``: kill processes at random (seeded) moments of a run, several at once and
while the clock is held for an earlier kill's restart, and check that the vehicles fly exactly
as they do without a fault.

Two runs of the scenario's stack (router, recorder, plume, physics, the autopilots — one per
``vehicles_per_process`` vehicles —, gateway), each on a stepped clock (``time.mode =
"stepped"``; this process holds the clock, so every command lands on a known tick and two runs
give the same bits) for ``seconds`` of sim time: the vehicles' missions are uploaded, armed and
started on tick 1. The first run has no fault. In the second, ``faults`` processes in all are
sent SIGKILL, drawn from ``random.Random(seed)`` among those that may still be restarted (the
supervisor restarts each at most 3 times):

- at seeded ticks, a group of 1 to ``concurrent`` distinct processes at the same moment;
- after a seeded share (``in_hold``) of those groups, the world is stepped at once, without
  waiting for the group to be back — the physics holds the clock for the restarts (a tick
  waits for a restarted autopilot, plume, recorder, router or physics) — and a further group of
  1 to ``concurrent`` other processes is killed while the first is not back yet.

The physics holds the clock for every restart (docs/physics.md, "Restarts"): the comparison is
every vehicle's ``vehicle/<id>/state`` stream, tick by tick, byte for byte (a tick replayed
after a physics restart must repeat its first bytes).

The report (``chaos.json`` and the console) lists each fault (tick, the processes killed
together, whether it fell in a hold and for whom, how long until every one was back, how long
the step over it took) and whether anything differed.
"""

from __future__ import annotations

import json
import logging
import os
import random
import signal
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import zenoh

from agents.swarm import Swarm, SwarmError
from deploy.launcher import Launcher, LaunchError, LaunchOptions, plan
from deploy.scaling import ScalingError, local_stack_scenario, multirotors_only
from plumeswarm.experiments.demo import DemoError, start_missions
from plumeswarm.experiments.launch import NODE_COMMAND
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys
from swarmbus.scenario import Scenario
from swarmbus.views import state_key_decoder

log = logging.getLogger(__name__)

ROLES = ("router", "recorder", "plume", "physics", "autopilot", "gateway")
STEP_S = 0.1  # sim seconds per step between fault checks
BACK_TIMEOUT_S = 120.0  # wall: a killed process must be back within this
HOLD_KILL_S = (0.1, 0.6)  # wall: the second group goes this long after the first (seeded)


class ChaosError(PlumeswarmError, RuntimeError):
    """The chaos run could not be carried out: one line why."""


@dataclass(frozen=True)
class ChaosOptions:
    scenario: Scenario
    scenario_path: Path
    out: Path
    seconds: float
    seed: int
    faults: int = 20  # processes killed in all
    concurrent: int = 3  # at most this many killed at the same moment
    in_hold: float = 0.3  # share of the groups followed by a kill during their hold
    vehicles_per_process: int = 1


@dataclass
class Fault:
    tick: int  # the last tick whose states had come in when it struck
    processes: list[str]  # killed at the same moment
    in_hold: bool = False  # an earlier group was not back yet (the clock held for it)
    held_for: list[str] = field(default_factory=list)  # that group's processes not back
    back_s: float = 0.0  # SIGKILL → every one's token again
    step_s: float = 0.0  # the step over the fault (the clock held meanwhile)


@dataclass(frozen=True)
class Moment:
    """One planned fault: ``size`` processes at ``tick``; then ``hold_size`` more during the
    hold for their restarts (0: none, the run waits until they are back)."""

    tick: int
    size: int
    hold_size: int = 0


@dataclass
class ChaosRun:
    states: dict[str, dict[int, bytes]] = field(default_factory=dict)
    conflicts: list[tuple[str, int]] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    last_tick: int = 0
    held_s: float = 0.0  # the steps over the faults, in all
    latest_tick: int = -1  # the highest tick of a state seen so far
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_state(self, sample: zenoh.Sample) -> None:
        with self.lock:
            tick = keep_state(self.states, self.conflicts, sample.payload.to_bytes())
            self.latest_tick = max(self.latest_tick, tick)


def keep_state(
    states: dict[str, dict[int, bytes]], conflicts: list[tuple[str, int]], payload: bytes
) -> int:
    """Keep a ``VehicleState`` payload by vehicle and tick, the first seen; a later one of the
    same tick that differs (a replay that did not repeat its bits) is noted in ``conflicts``.
    Returns its tick."""
    k = state_key_decoder.decode(payload)
    if states.setdefault(k.vehicle_id, {}).setdefault(k.tick, payload) != payload:
        conflicts.append((k.vehicle_id, k.tick))
    return k.tick


def fault_plan(seed: int, count: int, first_tick: int, last_tick: int) -> list[int]:
    """``count`` distinct ticks in ``[first_tick, last_tick)``, from ``seed``."""
    if last_tick - first_tick < count:
        raise ChaosError(f"{count} faults do not fit in ticks {first_tick}..{last_tick}")
    return sorted(random.Random(seed).sample(range(first_tick, last_tick), count))


def moment_plan(
    seed: int, kills: int, concurrent: int, in_hold: float, first_tick: int, last_tick: int
) -> list[Moment]:
    """``kills`` processes in all, in groups of 1..``concurrent`` at seeded ticks of
    ``[first_tick, last_tick)``; a share ``in_hold`` of the groups (those that leave a kill to
    spare) followed by another group during their hold. The same arguments, the same plan."""
    rng = random.Random(seed)
    sizes: list[tuple[int, int]] = []
    left = kills
    while left > 0:
        size = rng.randint(1, min(concurrent, left))
        left -= size
        hold = 0
        if left > 0 and rng.random() < in_hold:
            hold = rng.randint(1, min(concurrent, left))
            left -= hold
        sizes.append((size, hold))
    ticks = fault_plan(seed, len(sizes), first_tick, last_tick)
    return [Moment(t, s, h) for t, (s, h) in zip(ticks, sizes, strict=True)]


def restart_budget(scenario: Scenario, vehicles_per_process: int) -> tuple[int, int]:
    """(processes, restarts in all) of the chaos run's stack: how many kills it can take."""
    specs = plan(
        scenario, _launch_options(Path("runs"), Path("scenario.toml"), vehicles_per_process)
    )
    return len(specs), sum(s.restart.max_restarts for s in specs)


def _launch_options(run_dir: Path, path: Path, vehicles_per_process: int) -> LaunchOptions:
    return LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        record=True,
        run_dir=run_dir,
        roles=ROLES,
        vehicles_per_process=vehicles_per_process,
    )


def _stepped(opts: ChaosOptions, run_dir: Path) -> tuple[Scenario, Path]:
    run_dir.mkdir(parents=True, exist_ok=True)
    return local_stack_scenario(opts.scenario, run_dir, "stepped")


class Stepper:
    """Steps the world on a thread of its own, so that this thread can supervise (restart)
    and kill meanwhile: the supervisor must spawn on the thread that started the stack."""

    def __init__(self, sw: Swarm) -> None:
        self.sw = sw
        self.tick: int | None = None
        self.error: str | None = None
        self._thread: threading.Thread | None = None

    def start(self, ticks: int) -> None:
        self.tick, self.error = None, None
        self._thread = threading.Thread(target=self._run, args=(ticks,), name="chaos-step")
        self._thread.start()

    def _run(self, ticks: int) -> None:
        deadline = time.monotonic() + BACK_TIMEOUT_S
        while True:
            try:
                self.tick = self.sw.step(ticks, timeout_s=30.0).tick
                return
            except SwarmError as exc:  # a restarted physics missed the request: ask again
                if time.monotonic() > deadline:
                    self.error = f"the world did not step: {exc}"
                    return
                log.warning("step again: %s", exc)

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def join(self) -> int:
        assert self._thread is not None
        self._thread.join()
        if self.error is not None:
            raise ChaosError(self.error)
        assert self.tick is not None
        return self.tick


class Killer:
    """Kills groups of processes of a launched stack and sees them back."""

    def __init__(self, launcher: Launcher, flight: ChaosRun, rng: random.Random) -> None:
        self.launcher = launcher
        self.flight = flight
        self.rng = rng
        self.down: dict[str, int] = {}  # killed, not back yet: name → the pid killed

    def eligible(self) -> list[str]:
        """Processes running that may still be restarted, and not down."""
        sup = self.launcher.supervisor
        return sorted(
            n
            for n, sv in sup.procs.items()
            if sv.restarts < sv.spec.restart.max_restarts
            and n not in self.down
            and sv.pid is not None
            and sv.proc is not None
            and sv.proc.poll() is None
        )

    def kill(self, size: int) -> Fault:
        """SIGKILL ``size`` distinct processes (fewer when fewer may be) at the same moment."""
        names = self.eligible()
        if not names:
            raise ChaosError("every process has used its restarts")
        group = sorted(self.rng.sample(names, min(size, len(names))))
        held_for = sorted(n for n in self.down if not self.is_back(n))
        pids = self.launcher.supervisor.pids()
        for name in group:
            os.killpg(pids[name], signal.SIGKILL)
        for name in group:
            self.down[name] = pids[name]
        with self.flight.lock:
            tick = self.flight.latest_tick
        return Fault(tick=tick, processes=group, in_hold=bool(held_for), held_for=held_for)

    def is_back(self, name: str) -> bool:
        """Restarted (another pid) and its token is there."""
        view = self.launcher.view
        pid = self.launcher.supervisor.pids().get(name)
        return pid != self.down.get(name) and view is not None and name in view.presence.alive

    def supervise(self) -> None:
        self.launcher.supervise_once()
        for name in [n for n in self.down if self.is_back(n)]:
            del self.down[name]

    def wait_back(self, faults: list[tuple[Fault, float]], stepper: Stepper | None) -> None:
        """Supervise until every process of ``faults`` (with the monotonic time each was
        killed) is back and ``stepper`` is done; fill in their ``back_s``."""
        deadline = time.monotonic() + BACK_TIMEOUT_S
        pending = [(f, t0) for f, t0 in faults if not f.back_s]
        while pending or (stepper is not None and stepper.running):
            self.supervise()
            now = time.monotonic()
            for fault, t0 in list(pending):
                if not any(n in self.down for n in fault.processes):
                    fault.back_s = now - t0
                    pending.remove((fault, t0))
            if now > deadline:
                late = sorted(n for f, _ in pending for n in f.processes if n in self.down)
                raise ChaosError(
                    f"{', '.join(late) or 'the step'} not back within {BACK_TIMEOUT_S:.0f} s"
                )
            time.sleep(0.05)


def fly(
    opts: ChaosOptions, run_dir: Path, moments: list[Moment], console: Callable[[str], None]
) -> ChaosRun:
    """One run; the faults of ``moments`` (see the module doc)."""
    sc, path = _stepped(opts, run_dir)
    flight = ChaosRun()
    keys = Keys(sc.world.name)
    subs: list[zenoh.Subscriber[None]] = []

    def on_bus(session: zenoh.Session) -> None:
        subs.append(session.declare_subscriber(keys.all_vehicle_states(), flight.on_state))

    launcher = Launcher(sc, _launch_options(run_dir, path, opts.vehicles_per_process))
    total = round(opts.seconds * sc.time.control_hz)
    chunk = max(1, round(STEP_S * sc.time.control_hz))
    try:
        launcher.start(on_bus)
        sw = Swarm(launcher.session, keys, own_session=False, command_timeout_s=5.0)
        killer = Killer(launcher, flight, random.Random(opts.seed + 1))
        stepper = Stepper(sw)
        try:
            reply = sw.step(1)
            start_missions(sw, sc, time.monotonic() + 60.0)
            tick, pending = reply.tick, list(moments)
            while tick < total:
                target = min(total, tick + chunk, *(m.tick for m in pending[:1]), total)
                if target > tick:
                    t0 = time.monotonic()
                    stepper.start(target - tick)
                    killer.wait_back([], stepper)
                    tick = stepper.join()
                    if flight.faults and flight.faults[-1].step_s == 0.0:
                        flight.faults[-1].step_s = time.monotonic() - t0
                        flight.held_s += flight.faults[-1].step_s
                if pending and tick >= pending[0].tick:
                    tick = _fault(killer, stepper, pending.pop(0), tick, total, chunk, console)
            flight.last_tick = tick
        finally:
            sw.close()
    finally:
        for sub in subs:
            sub.undeclare()
        launcher.stop()
    return flight


def _fault(
    killer: Killer,
    stepper: Stepper,
    moment: Moment,
    tick: int,
    total: int,
    chunk: int,
    console: Callable[[str], None],
) -> int:
    """Carry out one moment of the plan at ``tick``; the tick the world is at afterwards."""
    faults = killer.flight.faults
    t0 = time.monotonic()
    first = killer.kill(moment.size)
    faults.append(first)
    if not moment.hold_size:
        killer.wait_back([(first, t0)], None)
        _say(first, console)
        return tick
    # Step at once: the physics holds the clock for the restarts; strike again meanwhile.
    stepper.start(max(1, min(chunk, total - tick)))
    delay_s = killer.rng.uniform(*HOLD_KILL_S)
    while time.monotonic() - t0 < delay_s:
        killer.supervise()
        time.sleep(0.02)
    if not killer.eligible():  # every process left to kill is the first group's: after it
        killer.wait_back([(first, t0)], stepper)
    t1 = time.monotonic()
    second = killer.kill(moment.hold_size)
    faults.append(second)
    killer.wait_back([(first, t0), (second, t1)], stepper)
    tick = stepper.join()
    first.step_s = second.step_s = time.monotonic() - t0
    killer.flight.held_s += first.step_s
    _say(first, console)
    _say(second, console)
    return tick


def _say(fault: Fault, console: Callable[[str], None]) -> None:
    during = f" (during the hold for {', '.join(fault.held_for)})" if fault.in_hold else ""
    console(
        f"tick {fault.tick}: killed {', '.join(fault.processes)}{during}, "
        f"back after {fault.back_s:.1f} s"
    )


def compare(base: ChaosRun, chaos: ChaosRun) -> dict[str, object]:
    """Tick by tick, every vehicle's states: missing and differing ticks, replay conflicts."""
    out: dict[str, object] = {"conflicts": len(chaos.conflicts) + len(base.conflicts)}
    vehicles = {}
    for vid in sorted(base.states):
        got, want = chaos.states.get(vid, {}), base.states[vid]
        end = min(base.last_tick, chaos.last_tick)
        missing = [t for t in range(end + 1) if t not in got or t not in want]
        differ = [t for t in range(end + 1) if t in got and t in want and got[t] != want[t]]
        vehicles[vid] = {
            "ticks": end + 1,
            "missing": len(missing),
            "differ": len(differ),
            "first_differ": differ[0] if differ else None,
        }
    out["vehicles"] = vehicles
    out["identical"] = not out["conflicts"] and all(
        v["missing"] == 0 and v["differ"] == 0 for v in vehicles.values()
    )
    return out


def run_chaos(opts: ChaosOptions, console: Callable[[str], None]) -> int:
    """Both runs, the comparison and the report; 0 when the streams are identical."""
    control_hz = opts.scenario.time.control_hz
    total = round(opts.seconds * control_hz)
    try:
        multirotors_only(opts.scenario, "a restarted plane's autopilot does not resume bit for bit")
        first = 2 * round(STEP_S * control_hz)
        moments = moment_plan(opts.seed, opts.faults, opts.concurrent, opts.in_hold, first, total)
        n = len(opts.scenario.vehicles)
        console(
            f"fault-free run: {opts.seconds:g} s of sim time, {n} vehicles, "
            f"{opts.vehicles_per_process} per autopilot process"
        )
        base = fly(opts, opts.out / "fault-free", [], console)
        holds = sum(1 for m in moments if m.hold_size)
        console(
            f"chaos run: up to {opts.faults} processes killed at {len(moments) + holds} moments, "
            f"up to {opts.concurrent} at once, {holds} during a hold (seed {opts.seed})"
        )
        t0 = time.monotonic()
        load0 = os.getloadavg()[0]
        chaos = fly(opts, opts.out / "chaos", moments, console)
        wall_s = time.monotonic() - t0
        load1 = os.getloadavg()[0]
    except (ChaosError, LaunchError, DemoError, SwarmError, ScalingError) as exc:
        console(f"chaos: {exc}")
        return 2
    result = compare(base, chaos)
    held = chaos.held_s
    report = {
        "seed": opts.seed,
        "seconds": opts.seconds,
        "vehicle_count": n,
        "vehicles_per_process": opts.vehicles_per_process,
        "concurrent": opts.concurrent,
        "in_hold": opts.in_hold,
        "ticks": chaos.last_tick,
        "wall_s": wall_s,
        "load_average": [load0, load1],
        "faults": [asdict(f) for f in chaos.faults],
        "held_s": held,
        **result,
    }
    (opts.out / "chaos.json").write_text(json.dumps(report, indent=2) + "\n")
    _summary(chaos, wall_s, held, console)
    vehicles = result["vehicles"]
    assert isinstance(vehicles, dict)
    for vid, v in vehicles.items():
        console(f"  {vid}: {v['ticks']} ticks, {v['missing']} missing, {v['differ']} differ")
    verdict = "identical to the fault-free run" if result["identical"] else "DIFFERENT"
    console(f"state streams: {verdict} (report: {opts.out / 'chaos.json'})")
    return 0 if result["identical"] else 1


def _summary(chaos: ChaosRun, wall_s: float, held_s: float, console: Callable[[str], None]) -> None:
    by_role: dict[str, int] = {}
    for f in chaos.faults:
        for p in f.processes:
            by_role[p] = by_role.get(p, 0) + 1
    together = sum(1 for f in chaos.faults if len(f.processes) > 1)
    in_hold = sum(1 for f in chaos.faults if f.in_hold)
    console(
        f"{sum(by_role.values())} processes killed ("
        + ", ".join(f"{n} {p}" for p, n in sorted(by_role.items()))
        + f") at {len(chaos.faults)} moments ({together} of several at once, {in_hold} during "
        f"a hold) over {chaos.last_tick} ticks in {wall_s:.0f} s wall; "
        f"steps over the faults took {held_s:.1f} s in all"
    )
