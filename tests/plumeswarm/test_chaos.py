"""``plumeswarm chaos``: 20 processes (router, recorder, plume, physics, autopilots, gateway)
killed at seeded ticks of a stepped run of three Iris quads flying their missions, several at
the same moment and some while the clock is held for an earlier kill's restart; every vehicle's
state stream is compared, tick by tick and byte for byte, with a fault-free run. The comparison
itself is checked on doctored flights (it must see a missing tick, a differing byte and a
replay conflict); the plan of the kills is checked against its definition."""

from __future__ import annotations

import json
import re
from pathlib import Path

from plumeswarm.experiments.chaos import ChaosRun, compare, fault_plan, moment_plan
from tests.support.mavclient import write_scenario
from tests.support.procs import run_cli


def flight(ticks: int, vehicles: tuple[str, ...] = ("uav1", "uav2")) -> ChaosRun:
    f = ChaosRun(last_tick=ticks - 1)
    for vid in vehicles:
        f.states[vid] = {t: f"{vid}:{t}".encode() for t in range(ticks)}
    return f


def test_compare_sees_missing_differing_and_conflicting_ticks() -> None:
    assert compare(flight(10), flight(10))["identical"] is True
    missing = flight(10)
    del missing.states["uav2"][4]
    r = compare(flight(10), missing)
    assert r["identical"] is False and r["vehicles"]["uav2"]["missing"] == 1  # type: ignore[index]
    differ = flight(10)
    differ.states["uav1"][7] = b"other"
    r = compare(flight(10), differ)
    assert r["vehicles"]["uav1"] == {"ticks": 10, "missing": 0, "differ": 1, "first_differ": 7}  # type: ignore[index]
    conflict = flight(10)
    conflict.conflicts.append(("uav1", 3))
    assert compare(flight(10), conflict)["identical"] is False


def test_fault_plan_is_seeded_and_distinct() -> None:
    plan = fault_plan(7, 20, 24, 1200)
    assert plan == fault_plan(7, 20, 24, 1200) != fault_plan(8, 20, 24, 1200)
    assert len(set(plan)) == 20 and plan == sorted(plan) and plan[0] >= 24 and plan[-1] < 1200


def test_moment_plan_is_seeded_and_spends_the_kills() -> None:
    plan = moment_plan(3, 20, 3, 0.3, 24, 1200)
    assert plan == moment_plan(3, 20, 3, 0.3, 24, 1200) != moment_plan(4, 20, 3, 0.3, 24, 1200)
    assert sum(m.size + m.hold_size for m in plan) == 20
    assert all(1 <= m.size <= 3 and 0 <= m.hold_size <= 3 for m in plan)
    ticks = [m.tick for m in plan]
    assert ticks == sorted(set(ticks)) and ticks[0] >= 24 and ticks[-1] < 1200
    assert any(m.size > 1 for m in plan) and any(m.hold_size for m in plan)
    one_by_one = moment_plan(3, 20, 1, 0.0, 24, 1200)
    assert [(m.size, m.hold_size) for m in one_by_one] == [(1, 0)] * 20


def test_chaos_twenty_faults_streams_identical(tmp_path: Path) -> None:
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 3)
    out = tmp_path / "run"
    args = ["chaos", str(path), "--seconds", "10", "--faults", "20", "--seed", "3"]
    r = run_cli([*args, "--out", str(out)], timeout_s=600.0)
    print(r.stdout[-3000:])
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = json.loads((out / "chaos.json").read_text())
    killed = [p for f in report["faults"] for p in f["processes"]]
    assert len(killed) == 20
    roles = {p.split("-")[0] for p in killed}
    assert len(roles) >= 4, roles
    together = [f for f in report["faults"] if len(f["processes"]) > 1]
    assert together, "no processes killed at the same moment"
    assert all(len(set(f["processes"])) == len(f["processes"]) for f in together)
    held = [f for f in report["faults"] if f["in_hold"]]
    assert held, "no fault during a hold"
    for f in held:  # the processes it was held for were killed earlier, and are others
        assert f["held_for"] and not set(f["held_for"]) & set(f["processes"]), f
    for f in report["faults"]:
        assert 0.0 < f["back_s"] < 120.0, f
    assert report["identical"] and report["conflicts"] == 0
    for vid, v in report["vehicles"].items():
        assert v["ticks"] == 1201 and v["missing"] == 0 and v["differ"] == 0, vid
    assert "identical to the fault-free run" in r.stdout


def test_chaos_physics_and_an_autopilot_killed_before_the_checkpoint_after_the_commands(
    tmp_path: Path,
) -> None:
    """Seed 13 kills autopilot-uav2 and the physics together at tick 90: the physics resumes
    from its checkpoint of tick 0, before the missions' commands of tick 1. The autopilots
    that ran on and the restarted one handle those commands again in the replay, where they
    came: the streams are the fault-free run's."""
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 3)
    out = tmp_path / "run"
    args = ["--seconds", "2", "--faults", "2", "--concurrent", "2", "--in-hold", "0"]
    r = run_cli(["chaos", str(path), *args, "--seed", "13", "--out", str(out)], timeout_s=300.0)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = json.loads((out / "chaos.json").read_text())
    [fault] = report["faults"]
    assert fault["processes"] == ["autopilot-uav2", "physics"] and fault["tick"] < 120, fault
    physics = (out / "chaos" / "physics.log").read_text()
    assert "resumed from checkpoint at tick 0 " in physics
    for vid in ("uav1", "uav2"):
        log = (out / "chaos" / f"autopilot-{vid}.log").read_text()
        assert re.search(r"tick 1: \d+ command\(s\) handled again in the replay", log), vid
    assert report["identical"] and report["conflicts"] == 0


def test_chaos_bad_input_is_one_line() -> None:
    bad = (
        ["--seconds", "0"],
        ["--faults", "0"],
        ["no-such-scenario.toml"],
        ["--faults", "25"],  # 8 processes (3 vehicles), 3 restarts each: 24
        ["--concurrent", "0"],
        ["--in-hold", "1.5"],
    )
    for args in bad:
        r = run_cli(["chaos", *args], timeout_s=60.0)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert r.stderr.startswith("plumeswarm: error:") and "Traceback" not in r.stderr, args
