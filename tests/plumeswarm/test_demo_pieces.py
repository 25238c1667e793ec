"""The demo's pieces without the stack: scaling, the state digest, samples, tables, summary."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from deploy.busview import Snapshot, VehicleView
from deploy.scaling import scale_scenario, scenario_toml, write_scenario
from plumeswarm.experiments.demo import (
    StateDigest,
    VehicleRecord,
    accuracy_table,
    live_table,
    pick_samples,
    vehicle_summary,
)
from swarmbus.codec import encode
from swarmbus.messages import (
    ConcentrationReading,
    FlightMode,
    VehicleState,
    VehicleStatus,
)
from swarmbus.scenario import load_scenario, parse_scenario
from tests.support.messages_samples import reading as noiseless_reading
from tests.support.messages_samples import vehicle_state
from tests.support.procs import run_cli


def state(vid: str, tick: int, x: float = 0.0) -> VehicleState:
    return vehicle_state(vid, tick, (x, 0.0, 10.0))


def reading(t: float, pos: tuple[float, float, float], value: float | None) -> ConcentrationReading:
    return noiseless_reading("uav1", t, pos, value)


def status(**kw: object) -> VehicleStatus:
    base: dict[str, object] = {
        "vehicle_id": "uav1",
        "sim_time_s": 1.0,
        "mode": FlightMode.DISARMED,
        "armed": False,
        "landed": True,
    }
    base.update(kw)
    return VehicleStatus(**base)  # type: ignore[arg-type]


# ---------------------------------------------------------------------------- scaling
def test_scaling_to_the_same_count_is_the_scenario() -> None:
    sc = load_scenario()
    assert scale_scenario(sc, len(sc.vehicles)) is sc


@pytest.mark.parametrize("n", [1, 5, 8, 16])
def test_scaling_spawns_a_grid_with_offset_missions(n: int) -> None:
    sc = load_scenario()
    scaled = scale_scenario(sc, n)
    assert [v.id for v in scaled.vehicles] == [f"uav{k + 1}" for k in range(n)]
    assert len({scaled.sysid_of(v.id) for v in scaled.vehicles}) == n
    spawns = {v.spawn_enu_m for v in scaled.vehicles}
    assert len(spawns) == n, "every vehicle has its own spawn point"
    for k, v in enumerate(scaled.vehicles):
        template = sc.vehicles[k % len(sc.vehicles)]
        assert len(v.mission) == len(template.mission)
        dx = v.spawn_enu_m[0] - template.spawn_enu_m[0]
        dy = v.spawn_enu_m[1] - template.spawn_enu_m[1]
        for mine, theirs in zip(v.mission, template.mission, strict=True):
            assert mine.command == theirs.command
            assert (mine.x, mine.y) == pytest.approx((theirs.x + dx, theirs.y + dy))
        # the mission starts above its own spawn point and lands back on it
        assert (v.mission[0].x, v.mission[0].y) == pytest.approx(v.spawn_enu_m[:2])
        assert v.mission[-1].z == 0.0
    # the scaled scenario survives a round trip through its TOML file
    assert parse_scenario(scenario_toml(scaled)) == scaled


def test_write_scenario_round_trips(tmp_path: Path) -> None:
    sc = scale_scenario(load_scenario(), 4)
    path = write_scenario(sc, tmp_path / "s.toml")
    assert parse_scenario(path.read_text()) == sc
    result = run_cli(["scenario", "check", str(path)])
    assert result.returncode == 0 and "4 vehicle(s)" in result.stdout


def test_scaling_rejects_zero() -> None:
    with pytest.raises(ValueError, match="at least 1"):
        scale_scenario(load_scenario(), 0)


# ---------------------------------------------------------------------------- digest
def test_digest_is_independent_of_arrival_order_and_repeats() -> None:
    payloads = [encode(state(v, t, x=t * 0.1)) for t in range(5) for v in ("uav1", "uav2")]
    a, b = StateDigest(), StateDigest()
    for p in payloads:
        a.add(p)
    for p in reversed(payloads + payloads[:3]):  # reordered, tick 0 re-published
        b.add(p)
    ra, rb = a.result(), b.result()
    assert ra["sha256"] == rb["sha256"]
    assert ra["messages"] == 10 and ra["first_tick"] == 0 and ra["last_tick"] == 4
    assert ra["missing"] == 0 and rb["conflicts"] == 0


def test_digest_changes_with_any_state_and_counts_gaps_and_garbage() -> None:
    a, b = StateDigest(), StateDigest()
    for t in (0, 1, 3):
        a.add(encode(state("uav1", t)))
        b.add(encode(state("uav1", t, x=1e-9 if t == 3 else 0.0)))
    a.add(b"garbage")
    assert a.result()["sha256"] != b.result()["sha256"]
    assert a.result()["missing"] == 1 and a.result()["undecodable"] == 1
    b.add(encode(state("uav1", 3)))
    assert b.result()["conflicts"] == 1


# ---------------------------------------------------------------------------- records
def test_vehicle_record_needs_a_finished_mission_then_touchdown() -> None:
    rec = VehicleRecord()
    rec.on_status(status(mission_finished=True))  # before flying: a stale flag, not a flight
    assert not rec.done
    rec.on_status(status(mode=FlightMode.MISSION, armed=True, landed=False))
    rec.on_status(status(mode=FlightMode.LAND, armed=True, landed=False, mission_finished=True))
    assert rec.mission_finished and not rec.done
    rec.on_status(status(mode=FlightMode.DISARMED, armed=False, landed=True, mission_finished=True))
    assert rec.done


def test_samples_prefer_the_sensor_window_and_spread_over_the_flight() -> None:
    rs = [reading(0.0, (0.0, 0.0, 0.0), 0.0)]  # on the ground: never a sample
    rs += [reading(1 + i, (float(i), 0.0, 10.0), 0.2 if i % 2 else 0.05) for i in range(20)]
    rs += [reading(30.0, (5.0, 0.0, 10.0), None)]  # unavailable: never a sample
    picked = pick_samples(rs, (0.01, 0.2), 5)
    assert len(picked) == 5
    assert all(p.reported_g_m3 == 0.05 for p in picked)
    assert picked[0].sim_time_s == 1 and picked[-1].sim_time_s == 19
    assert pick_samples(rs[:3], (0.01, 0.2), 5) == rs[1:3]


def test_vehicle_summary_and_accuracy_table_use_the_model_at_the_reported_position() -> None:
    rec = VehicleRecord()
    rec.readings = [reading(1 + i, (float(i), 1.0, 10.0), 0.01 * (i + 2)) for i in range(10)]
    rec.on_status(status(mode=FlightMode.MISSION, armed=True, landed=False))
    rec.on_status(status(armed=False, landed=True, mission_finished=True))

    def model(points: np.ndarray, times: object) -> np.ndarray:
        return points[:, 0] * 0.01 + 0.015  # a stand-in field, linear in x

    summary = vehicle_summary(rec, (9.0, 1.0, 0.0), model, (0.01, 0.2))
    assert summary["mission_completed"] and summary["landed"]
    assert summary["readings"] == 10 and summary["max_concentration_g_m3"] == pytest.approx(0.11)
    assert summary["final_position"] == [9.0, 1.0, 0.0]
    assert len(summary["samples"]) == 5
    for row in summary["samples"]:
        assert row["model_g_m3"] == pytest.approx(row["x"] * 0.01 + 0.015)
    json.dumps(summary)
    table = accuracy_table({"uav1": summary})
    lines = table.splitlines()
    assert "reported" in lines[0] and "model" in lines[0] and "diff" in lines[0]
    assert len(lines) == 2 + 5
    assert lines[2].split()[-1] == f"{0.02 - 0.015:.5f}"


def test_live_table_lists_every_vehicle() -> None:
    snap = Snapshot(
        clock=None,
        alive=frozenset({"physics"}),
        health={},
        vehicles={"uav1": VehicleView("uav1", state("uav1", 3, x=12.5), status(), None)},
    )
    text = live_table(snap, {"uav1": VehicleRecord(), "uav2": VehicleRecord()}, 2)
    assert "12.50" in text and "uav2" in text and "flying 0/2" in text


def test_scaling_past_mavlink_keeps_sysids_for_the_first_254_only(tmp_path: Path) -> None:
    scaled = scale_scenario(load_scenario(), 256)
    back = load_scenario(write_scenario(scaled, tmp_path / "s256.toml"))
    assert [back.sysid_of(f"uav{k}") for k in (1, 254, 255, 256)] == [1, 254, None, None]
    assert back.not_on_mavlink() == ["uav255", "uav256"]
