"""The physics process over a real Zenoh network with scripted participants in other processes:
the lockstep with its participants (a slow, killed, stalled or late one), start-up and realtime
runs, and its options. Batches and determinism: test_physics_batches.py; the plume sample:
test_physics_plume.py."""

from __future__ import annotations

from pathlib import Path

import pytest

from swarmbus.codec import encode
from swarmbus.messages import ActuatorBatch, ActuatorCommand
from tests.support.physics_rig import (
    KEYS,
    Watch,
    exit_code,
    fly_a_and_b,
    report,
    start_script,
    stream_hash,
    two_vehicle_scenario,
)
from tests.support.procs import NodeProcs, run_cli, wait_until


def test_lockstep_holds_while_a_participant_delays_its_answer(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, timeout_s=10.0)
    physics = procs.start("physics", "--scenario", str(sc), "--set", "max_ticks=60", name="physics")
    slow = start_script(
        procs, sc, "--vehicle", "a", "--throttle", "0.3", "--delay-tick", "30", "--delay-s",
        "1.0", "--max-tick", "60", "--report", str(tmp_path / "a.json"), label="script-a",
    )  # fmt: skip
    fast = start_script(
        procs, sc, "--vehicle", "b", "--throttle", "0.3", "--max-tick", "60",
        "--report", str(tmp_path / "b.json"), label="script-b",
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    assert exit_code(slow, "participant a") == 0
    assert exit_code(fast, "participant b") == 0
    ra, rb = report(tmp_path / "a.json"), report(tmp_path / "b.json")
    assert ra["violations"] == [] and rb["violations"] == []
    assert ra["answered"] == 60 and rb["answered"] == 60
    # While a sat on tick 30 for a second, no later tick was published.
    assert ra["delayed"] is True and ra["seen_while_delaying"] == []
    wait_until(lambda: watch.last_tick == 60, 10.0, "tick 60 at the test's subscriber")
    assert all(watch.motors[k] == {"a": True, "b": True} for k in range(1, 61))


def test_sigkilled_participant_is_dropped_others_go_on_and_a_restart_rejoins(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, timeout_s=1.0)
    victim = fly_a_and_b(procs, sc)
    wait_until(lambda: watch.last_tick >= 20, 60.0, "tick 20")
    procs.kill(victim)
    killed_at = watch.last_tick
    dropped = wait_until(
        lambda: watch.first_tick_after(killed_at, "a", False), 30.0, "a's motors to go off"
    )
    wait_until(lambda: watch.last_tick >= dropped + 100, 30.0, "100 more ticks without a")
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a2")
    back = wait_until(
        lambda: watch.first_tick_after(dropped, "a", True), 60.0, "a to be admitted again"
    )
    wait_until(lambda: watch.last_tick >= back + 20, 30.0, "ticks with a back in")
    wait_until(
        lambda: watch.clock is not None and watch.clock.participants == ["a", "b"],
        10.0,
        "sim/clock to list both participants",
    )


def test_stalled_participant_is_dropped_at_the_timeout_and_rejoins(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    # without the grace a late participant is dropped at the timeout (the default waits)
    sc = two_vehicle_scenario(tmp_path, timeout_s=0.5, extra_time="unreachable_grace_s = 0.0")
    fly_a_and_b(procs, sc, "--stall-at-tick", "20", "--stall-s", "2.0")
    dropped = wait_until(lambda: watch.first_tick_after(20, "a", False), 60.0, "a dropped")
    assert all(watch.motors[k]["a"] for k in range(1, 21))  # it answered those in time
    wait_until(lambda: watch.last_tick >= dropped + 50, 30.0, "ticks go on without a")
    wait_until(lambda: watch.first_tick_after(dropped, "a", True), 60.0, "a rejoined")


def test_a_late_participant_is_waited_for_and_the_stream_is_the_same_bits(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """Lockstep, default grace: a participant (flying a and b) whose token is up answers tick 20
    after 2 s, four times the 0.5 s timeout (a process starved on a loaded machine). Nothing is
    dropped, and the tick stream is the bits of a run without the delay."""
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, timeout_s=0.5)
    straight = stream_hash(procs, watch, sc, 120, "straight")
    late = stream_hash(procs, watch, sc, 120, "late", "--delay-tick", "20", "--delay-s", "2.0")
    assert late == straight
    log = (tmp_path / "physics-late.log").read_text()
    assert "tick 20: no answer from a, b for 0.50 s: holding the clock up to 30.0 s in all" in log
    assert all(all(watch.motors[k].values()) for k in range(1, 121))  # never dropped


def test_late_joiner_is_admitted(rig: tuple[NodeProcs, Watch], tmp_path: Path) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, timeout_s=1.0)
    procs.start(
        "physics", "--scenario", str(sc), "--set", "wait_for_autopilots=false", name="physics"
    )
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a")
    wait_until(lambda: watch.first_tick_after(0, "a", True), 60.0, "a's motors on")
    joined_from = watch.last_tick
    assert watch.motors[joined_from]["b"] is False  # nobody flies b yet
    # Garbage, a command on another vehicle's key and a command without a token change nothing.
    watch.session.put(KEYS.autopilot_actuators("autopilot-b"), b"\x00garbage")
    for key_vid in ("a", "b"):
        cmd = ActuatorCommand(vehicle_id="b", tick=watch.last_tick, rotor_commands=[1.0] * 6)
        batch = ActuatorBatch(tick=cmd.tick, commands=[cmd])
        watch.session.put(KEYS.autopilot_actuators(f"autopilot-{key_vid}"), encode(batch))
    wait_until(lambda: watch.last_tick >= joined_from + 50, 30.0, "ticks go on")
    assert watch.first_tick_after(joined_from, "b", True) == 0
    start_script(procs, sc, "--vehicle", "b", "--throttle", "0.2", label="script-b")
    wait_until(lambda: watch.first_tick_after(joined_from, "b", True), 60.0, "b admitted")


def test_missing_autopilots_fail_start_up_naming_them(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, _ = rig
    sc = two_vehicle_scenario(tmp_path, startup_s=1.0)
    physics = procs.start("physics", "--scenario", str(sc), name="physics")
    assert exit_code(physics, "physics") == 1
    log = (tmp_path / "physics.log").read_text()
    assert "autopilots missing" in log and "a, b" in log and "autopilot-a" in log


def test_realtime_mode_with_a_duration_ends_at_that_sim_time(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(
        tmp_path, extra_time='mode = "realtime"\nspeed_factor = 4.0\nduration_s = 1.0'
    )
    physics = procs.start(
        "physics", "--scenario", str(sc), "--set", "wait_for_autopilots=false", name="physics"
    )
    assert exit_code(physics, "physics") == 0
    wait_until(lambda: watch.last_tick == 120, 10.0, "tick 120 (1 s at 120 Hz)")
    wait_until(lambda: watch.clock is not None and watch.clock.tick == 120, 10.0, "final clock")
    assert watch.clock is not None and watch.clock.mode == "realtime"
    assert watch.clock.sim_time_s == pytest.approx(1.0)


def test_unknown_option_is_a_clear_error(tmp_path: Path) -> None:
    result = run_cli(
        ["node", "physics", "--scenario", str(two_vehicle_scenario(tmp_path)), "--set", "warp=9"]
    )
    assert result.returncode == 2
    assert "--set warp=9: unknown option; known: checkpoint," in result.stderr
