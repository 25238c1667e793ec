"""``plumeswarm chaos``: 20 processes (router, recorder, plume, physics, autopilots, gateway)
killed at seeded ticks of a stepped run of three Iris quads flying their missions; every
vehicle's state stream is compared, tick by tick and byte for byte, with a fault-free run.
The comparison itself is checked on doctored flights (it must see a missing tick, a differing
byte and a replay conflict)."""

from __future__ import annotations

import json
from pathlib import Path

from plumeswarm.experiments.chaos import ChaosRun, compare, fault_plan
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


def test_chaos_twenty_faults_streams_identical(tmp_path: Path) -> None:
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 3)
    out = tmp_path / "run"
    args = ["chaos", str(path), "--seconds", "10", "--faults", "20", "--seed", "3"]
    r = run_cli([*args, "--out", str(out)], timeout_s=600.0)
    print(r.stdout[-3000:])
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-3000:]
    report = json.loads((out / "chaos.json").read_text())
    assert len(report["faults"]) == 20
    roles = {f["process"].split("-")[0] for f in report["faults"]}
    assert len(roles) >= 4, roles
    assert report["identical"] and report["conflicts"] == 0
    for vid, v in report["vehicles"].items():
        assert v["ticks"] == 1201 and v["missing"] == 0 and v["differ"] == 0, vid
    assert "identical to the fault-free run" in r.stdout


def test_chaos_bad_input_is_one_line() -> None:
    for args in (["--seconds", "0"], ["--faults", "0"], ["no-such-scenario.toml"]):
        r = run_cli(["chaos", *args], timeout_s=60.0)
        assert r.returncode == 2, (args, r.stdout, r.stderr)
        assert r.stderr.startswith("plumeswarm: error:") and "Traceback" not in r.stderr, args
