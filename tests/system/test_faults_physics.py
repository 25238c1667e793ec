"""SIGKILL the physics process while three vehicles hold at altitude under ``plumeswarm up
--headless`` (the stack of ``tests/system/test_faults_stack.py``): the supervisor restarts it, it
resumes from its last checkpoint (not from the spawn), the autopilots restore their state of the
tick before the checkpoint's and fly the replay again. Replayed sim time and recovery times are
printed (-s)."""

from __future__ import annotations

import re
import time
from dataclasses import dataclass
from pathlib import Path

import zenoh

from deploy.launcher import Launcher, LaunchOptions, checkpoint_path
from deploy.supervisor import RestartMode
from sim_world import checkpoint
from sim_world.world import World
from swarmbus.codec import decode
from swarmbus.messages import FlightMode, NodeHealth, VehicleState, VehicleStatus
from swarmbus.scenario import load_scenario
from swarmbus.session import free_tcp_port
from tests.support.mavclient import write_scenario
from tests.support.procs import NODE_COMMAND, wait_until
from tests.system import test_faults_stack

VEHICLES = test_faults_stack.VEHICLES
ALTITUDE_M = test_faults_stack.ALTITUDE_M
Stack = test_faults_stack.Stack
stack = test_faults_stack.stack  # the same fixture: a stack of this module's own
HOLD_TOLERANCE_M = 3.0


@dataclass(frozen=True)
class Seen:
    wall: float
    tick: int
    position: tuple[float, float, float]


def resume_index(seq: list[Seen], noted_tick: int) -> int:
    """Where the restarted physics' states begin: the first tick that does not advance (it
    went back to the checkpoint). If none did, the old process was killed after saving the
    checkpoint of a tick and before publishing it, and the new one went on from exactly that
    tick: its states begin at the only state of the tick its health note names. (Not the first
    state seen once the new process was known: under load it publishes several ticks before
    the supervisor's restart is noticed.)"""
    back = next((i for i in range(1, len(seq)) if seq[i].tick <= seq[i - 1].tick), None)
    return back if back is not None else next(i for i, s in enumerate(seq) if s.tick == noted_tick)


def test_physics_killed_resumes_from_checkpoint_and_vehicles_fly_on(stack: Stack) -> None:
    scenario = load_scenario(stack.up.run.parent / "scenario.toml")
    control_hz = scenario.time.control_hz
    period_ticks = round(scenario.time.checkpoint_period_s * control_hz)
    assert period_ticks > 0
    states: list[tuple[str, Seen]] = []
    statuses: list[VehicleStatus] = []
    health: list[NodeHealth] = []

    def on_state(sample: zenoh.Sample) -> None:
        s = decode(sample.payload.to_bytes(), VehicleState)
        states.append((s.vehicle_id, Seen(time.monotonic(), s.tick, s.position_enu_m)))

    def on_status(sample: zenoh.Sample) -> None:
        statuses.append(decode(sample.payload.to_bytes(), VehicleStatus))

    def on_health(sample: zenoh.Sample) -> None:
        health.append(decode(sample.payload.to_bytes(), NodeHealth))

    keys, session = stack.keys, stack.session
    subs = [
        session.declare_subscriber(keys.all_vehicle_states(), on_state),
        session.declare_subscriber(keys.all_vehicle_status(), on_status),
        session.declare_subscriber(keys.node_health("physics"), on_health),
    ]
    try:
        wait_until(
            lambda: all(
                (s := stack.status.get(v)) is not None and s.mode == FlightMode.HOLD and s.armed
                for v in VEHICLES
            ),
            60.0,
            "every vehicle holding",
        )
        wait_until(lambda: len(states) > 30, 60.0, "states on our subscriber")
        hold = {v: stack.states[v].position_enu_m for v in VEHICLES}
        autopilots = {n: p for n, p in stack.pids().items() if n.startswith("autopilot-")}
        statuses.clear()
        ticks_at_kill = max(s.tick for _, s in states)
        pid, restart_s, _ = stack.up.kill("physics")
        t_kill = time.monotonic() - restart_s
        end_tick = ticks_at_kill + 3 * period_ticks
        wait_until(lambda: all(stack.tick_of(v) > end_tick for v in VEHICLES), 120.0, "ticks go on")
        seq = [s for v, s in list(states) if v == VEHICLES[0]]  # in arrival order
        note = wait_until(
            lambda: next(
                (h.detail for h in reversed(health) if "resumed from checkpoint" in h.detail), ""
            ),
            30.0,
            "the restarted physics' health note saying where it resumed",
        )
        noted = re.search(r"resumed from checkpoint at tick (\d+) ", note)
        assert noted is not None, note
        new = resume_index(seq, int(noted[1]))
        last_seen, first = seq[new - 1].tick, seq[new]
        resumed_tick = first.tick
        advancing = next(s for s in seq[new:] if s.tick > resumed_tick)
        caught_up = next(s for s in seq[new:] if s.tick > last_seen)
    finally:
        for s in subs:
            s.undeclare()

    # resumed from a checkpoint on the checkpoint schedule, at most one period back
    assert first.wall > t_kill and last_seen >= ticks_at_kill
    assert stack.pids()["physics"] == pid
    assert resumed_tick > 0 and resumed_tick % period_ticks == 0, (resumed_tick, period_ticks)
    replayed_ticks = max(0, last_seen - resumed_tick)
    assert replayed_ticks <= period_ticks, (last_seen, resumed_tick)
    assert f"resumed from checkpoint at tick {resumed_tick} " in note, note
    # every vehicle flew on near its hold position; no autopilot restarted, crashed or disarmed
    after = [(v, s) for v, s in states if s.wall >= first.wall]
    assert after
    for vid, seen in after:
        assert seen.position[2] > ALTITUDE_M - HOLD_TOLERANCE_M, (vid, seen)
    for vid in VEHICLES:
        x, y, z = stack.states[vid].position_enu_m
        hx, hy, hz = hold[vid]
        assert ((x - hx) ** 2 + (y - hy) ** 2 + (z - hz) ** 2) ** 0.5 < HOLD_TOLERANCE_M, vid
    assert {n: p for n, p in stack.pids().items() if n.startswith("autopilot-")} == autopilots
    assert statuses, "no vehicle status after the kill"
    # the autopilots went back with the physics (the state of the checkpoint's tick, which may
    # still be the end of the take-off) and flew the replay again: never disarmed or crashed
    bad = [s for s in statuses if not s.armed or s.crashed]
    assert not bad, bad[:3]
    assert all(stack.status[v].mode == FlightMode.HOLD for v in VEHICLES)
    print(
        f"physics: restarted in {restart_s:.1f} s; resumed at tick {resumed_tick} "
        f"(sim t={resumed_tick / control_hz:.3f} s), replayed {replayed_ticks / control_hz:.3f} s "
        f"of sim time (period {scenario.time.checkpoint_period_s:g} s); first tick of the new "
        f"process {first.wall - t_kill:.1f} s after the kill, ticks advancing after "
        f"{advancing.wall - t_kill:.1f} s, past the pre-kill tick after "
        f"{caught_up.wall - t_kill:.1f} s; physics says: {note}"
    )


def test_a_new_run_starts_from_spawn_not_from_a_checkpoint_left_in_its_directory(
    tmp_path: Path,
) -> None:
    """``up`` gives physics a checkpoint in the run directory and the on-failure policy; an
    earlier run's checkpoint there is removed, so the new physics starts from the spawn."""
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 1)
    scenario = load_scenario(path)
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        run_dir=tmp_path / "run",
        connect=(f"tcp/127.0.0.1:{free_tcp_port()}",),
        roles=("router", "physics"),  # physics is ready (waiting for its autopilot) at once
    )
    stale = checkpoint_path(opts)
    stale.parent.mkdir()
    with World(scenario) as world:
        checkpoint.save(stale, world.checkpoint(tick=999_960))
    with Launcher(scenario, opts) as launcher:
        physics = next(s for s in launcher.specs if s.role == "physics")
        assert f"checkpoint={stale}" in physics.argv
        assert physics.restart.mode is RestartMode.ON_FAILURE
        fresh = wait_until(
            lambda: stale.exists() and checkpoint.load(stale), 30.0, "the new run's checkpoint"
        )
    assert fresh.tick == 0
    log = (opts.run_dir / "physics.log").read_text()
    assert "resumed from checkpoint" not in log
