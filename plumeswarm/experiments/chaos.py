"""``plumeswarm chaos``: kill processes at random (seeded) moments of a run and check that the
vehicles fly exactly as they do without a fault.

Two runs of the scenario's stack (router, recorder, plume, physics, the autopilots, gateway),
each on a stepped clock (``time.mode = "stepped"``; this process holds the clock, so every
command lands on a known tick and two runs give the same bits) for ``seconds`` of sim time:
the vehicles' missions are uploaded, armed and started on tick 1. The first run has no fault.
In the second, at ``faults`` ticks drawn from ``random.Random(seed)``, one process drawn from
those that may still be restarted (the supervisor restarts each at most 3 times) is sent
SIGKILL; the run goes on stepping once it is back (its liveliness token again). The physics
holds the clock for every restart (docs/physics.md, "Restarts"): the comparison is every
vehicle's ``vehicle/<id>/state`` stream, tick by tick, byte for byte (a tick replayed after a
physics restart must repeat its first bytes).

The report (``chaos.json`` and the console) lists each fault (tick, process, how long until it
was back, how long the step over it took) and whether anything differed.
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
from deploy.launcher import Launcher, LaunchError, LaunchOptions
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


class ChaosError(PlumeswarmError, RuntimeError):
    """The chaos run could not be carried out: one line why."""


@dataclass(frozen=True)
class ChaosOptions:
    scenario: Scenario
    scenario_path: Path
    out: Path
    seconds: float
    seed: int
    faults: int = 20


@dataclass
class Fault:
    tick: int
    process: str
    back_s: float = 0.0  # SIGKILL → its token again
    step_s: float = 0.0  # the step over the fault (the clock held meanwhile)


@dataclass
class ChaosRun:
    states: dict[str, dict[int, bytes]] = field(default_factory=dict)
    conflicts: list[tuple[str, int]] = field(default_factory=list)
    faults: list[Fault] = field(default_factory=list)
    last_tick: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock)

    def on_state(self, sample: zenoh.Sample) -> None:
        with self.lock:
            keep_state(self.states, self.conflicts, sample.payload.to_bytes())


def keep_state(
    states: dict[str, dict[int, bytes]], conflicts: list[tuple[str, int]], payload: bytes
) -> None:
    """Keep a ``VehicleState`` payload by vehicle and tick, the first seen; a later one of the
    same tick that differs (a replay that did not repeat its bits) is noted in ``conflicts``."""
    k = state_key_decoder.decode(payload)
    if states.setdefault(k.vehicle_id, {}).setdefault(k.tick, payload) != payload:
        conflicts.append((k.vehicle_id, k.tick))


def fault_plan(seed: int, count: int, first_tick: int, last_tick: int) -> list[int]:
    """``count`` distinct ticks in ``[first_tick, last_tick)``, from ``seed``."""
    if last_tick - first_tick < count:
        raise ChaosError(f"{count} faults do not fit in ticks {first_tick}..{last_tick}")
    return sorted(random.Random(seed).sample(range(first_tick, last_tick), count))


def _stepped(opts: ChaosOptions, run_dir: Path) -> tuple[Scenario, Path]:
    run_dir.mkdir(parents=True, exist_ok=True)
    return local_stack_scenario(opts.scenario, run_dir, "stepped")


def fly(
    opts: ChaosOptions, run_dir: Path, faults: list[int], console: Callable[[str], None]
) -> ChaosRun:
    """One run; SIGKILL a process at each tick of ``faults`` (see the module doc)."""
    sc, path = _stepped(opts, run_dir)
    launch = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        record=True,
        run_dir=run_dir,
        roles=ROLES,
    )
    flight = ChaosRun()
    keys = Keys(sc.world.name)
    subs: list[zenoh.Subscriber[None]] = []

    def on_bus(session: zenoh.Session) -> None:
        subs.append(session.declare_subscriber(keys.all_vehicle_states(), flight.on_state))

    launcher = Launcher(sc, launch)
    rng = random.Random(opts.seed + 1)
    total = round(opts.seconds * sc.time.control_hz)
    chunk = max(1, round(STEP_S * sc.time.control_hz))
    try:
        launcher.start(on_bus)
        sw = Swarm(launcher.session, keys, own_session=False, command_timeout_s=5.0)
        try:
            reply = sw.step(1)
            start_missions(sw, sc, time.monotonic() + 60.0)
            tick, pending = reply.tick, list(faults)
            while tick < total:
                target = min(total, tick + chunk, *(pending[:1] or [total]))
                if target > tick:
                    t0 = time.monotonic()
                    tick = _step(sw, launcher, target - tick)
                    if flight.faults and flight.faults[-1].step_s == 0.0:
                        flight.faults[-1].step_s = time.monotonic() - t0
                if pending and tick >= pending[0]:
                    pending.pop(0)
                    fault = _kill_one(launcher, rng, tick)
                    flight.faults.append(fault)
                    console(f"tick {tick}: killed {fault.process}, back after {fault.back_s:.1f} s")
            flight.last_tick = tick
        finally:
            sw.close()
    finally:
        for sub in subs:
            sub.undeclare()
        launcher.stop()
    return flight


def _step(sw: Swarm, launcher: Launcher, ticks: int) -> int:
    """Step ``ticks`` (asked again if a restarted physics missed the request); the new tick."""
    deadline = time.monotonic() + BACK_TIMEOUT_S
    while True:
        launcher.supervise_once()
        try:
            return sw.step(ticks, timeout_s=30.0).tick
        except SwarmError as exc:
            if time.monotonic() > deadline:
                raise ChaosError(f"the world did not step: {exc}") from None
            log.warning("step again: %s", exc)


def _kill_one(launcher: Launcher, rng: random.Random, tick: int) -> Fault:
    """SIGKILL one process that may still be restarted; wait until its token is back."""
    sup = launcher.supervisor
    names = sorted(n for n, sv in sup.procs.items() if sv.restarts < sv.spec.restart.max_restarts)
    if not names:
        raise ChaosError("every process has used its restarts")
    name = rng.choice(names)
    old = sup.pids()[name]
    t0 = time.monotonic()
    os.killpg(old, signal.SIGKILL)
    while sup.pids().get(name) == old:
        launcher.supervise_once()
        if time.monotonic() - t0 > BACK_TIMEOUT_S:
            raise ChaosError(f"{name} was not restarted within {BACK_TIMEOUT_S:.0f} s")
        time.sleep(0.05)
    launcher.wait_ready([name], BACK_TIMEOUT_S)
    return Fault(tick=tick, process=name, back_s=time.monotonic() - t0)


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
        plan = fault_plan(opts.seed, opts.faults, 2 * round(STEP_S * control_hz), total)
        console(f"fault-free run: {opts.seconds:g} s of sim time")
        base = fly(opts, opts.out / "fault-free", [], console)
        console(f"chaos run: {len(plan)} faults (seed {opts.seed})")
        t0 = time.monotonic()
        chaos = fly(opts, opts.out / "chaos", plan, console)
        wall_s = time.monotonic() - t0
    except (ChaosError, LaunchError, DemoError, SwarmError, ScalingError) as exc:
        console(f"chaos: {exc}")
        return 2
    result = compare(base, chaos)
    held = sum(f.step_s for f in chaos.faults)
    report = {
        "seed": opts.seed,
        "seconds": opts.seconds,
        "ticks": chaos.last_tick,
        "wall_s": wall_s,
        "faults": [asdict(f) for f in chaos.faults],
        "held_s": held,
        **result,
    }
    (opts.out / "chaos.json").write_text(json.dumps(report, indent=2) + "\n")
    by_role: dict[str, int] = {}
    for f in chaos.faults:
        by_role[f.process] = by_role.get(f.process, 0) + 1
    console(
        f"{len(chaos.faults)} faults ("
        + ", ".join(f"{n} {p}" for p, n in sorted(by_role.items()))
        + f") over {chaos.last_tick} ticks in {wall_s:.0f} s wall; "
        f"steps over the faults took {held:.1f} s in all"
    )
    vehicles = result["vehicles"]
    assert isinstance(vehicles, dict)
    for vid, v in vehicles.items():
        console(f"  {vid}: {v['ticks']} ticks, {v['missing']} missing, {v['differ']} differ")
    verdict = "identical to the fault-free run" if result["identical"] else "DIFFERENT"
    console(f"state streams: {verdict} (report: {opts.out / 'chaos.json'})")
    return 0 if result["identical"] else 1
