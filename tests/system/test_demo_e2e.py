"""``plumeswarm demo`` end to end: the real stack flies the seed scenario and lands."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.image import imread

from recorder.report import READING_COLUMNS, TRACK_COLUMNS
from tests.recorder.test_report import PNGS
from tests.support.procs import run_cli


@pytest.fixture(scope="module")
def seed_demo(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """One ``plumeswarm demo`` of the seed scenario: its run directory and its output."""
    out = tmp_path_factory.mktemp("demo")
    result = run_cli(["demo", "--out", str(out), "--timeout", "600"], timeout_s=900)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    return out, result.stdout


def test_demo_flies_the_seed_scenario_and_writes_the_summary(seed_demo: tuple[Path, str]) -> None:
    tmp_path, stdout = seed_demo
    assert "every vehicle completed its mission and landed" in stdout
    assert "reported" in stdout and "model" in stdout
    assert "deterministic: stepped clock" in stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["ok"] and summary["scenario"]["vehicles"] == 3
    assert summary["clock"] == "stepped" and summary["deterministic"] is True
    assert summary["real_time_factor"] > 0
    digest = summary["state_digest"]
    assert len(digest["sha256"]) == 64 and digest["messages"] > 0
    assert digest["first_tick"] == 0 and digest["missing"] == 0 and digest["conflicts"] == 0
    for vid, v in summary["vehicles"].items():
        assert v["mission_completed"] and v["landed"], vid
        assert v["readings"] > 0 and v["readings_unavailable"] == 0, vid
        assert 0.01 < v["max_concentration_g_m3"] <= 0.2, vid
        assert v["final_position"][2] < 0.5, f"{vid} did not end on the ground"
        assert len(v["samples"]) == 5, vid
        for row in v["samples"]:
            # noise is off in the seed scenario: inside the sensor window, reported == model
            assert row["reported_g_m3"] == pytest.approx(row["model_g_m3"], rel=1e-9), (vid, row)
    pids = json.loads((tmp_path / "pids.json").read_text())
    assert {"router", "plume", "physics", "autopilot-uav1", "autopilot-uav3"} <= set(pids)
    _report_of_the_real_flight(Path(summary["recording"]), tmp_path / "report", summary)


def _report_of_the_real_flight(recording: Path, out: Path, summary: dict[str, Any]) -> None:
    """``plumeswarm report`` on the demo's own recording: every PNG drawn, every reading kept."""
    result = run_cli(["report", str(recording), "--out", str(out)], timeout_s=600)
    assert result.returncode == 0, result.stderr[-2000:]
    for name in PNGS:
        pixels = imread(out / name)
        assert np.var(pixels[..., :3]) > 1e-3, f"{name} is blank"
    for vid, v in summary["vehicles"].items():
        with open(out / f"{vid}_readings.csv") as f:
            rows = list(csv.reader(f))
        assert rows[0] == list(READING_COLUMNS)
        # the recorder ran from before take-off: it holds at least every reading the demo saw
        assert len(rows) - 1 >= v["readings"], vid
        with open(out / f"{vid}_track.csv") as f:
            track = list(csv.reader(f))
        assert track[0] == list(TRACK_COLUMNS) and len(track) > 100, vid


def test_demo_scales_to_more_vehicles(tmp_path: Path) -> None:
    result = run_cli(
        ["demo", "--vehicles", "5", "--out", str(tmp_path), "--timeout", "600"], timeout_s=900
    )
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert sorted(summary["vehicles"]) == [f"uav{k}" for k in range(1, 6)]
    assert all(v["mission_completed"] and v["landed"] for v in summary["vehicles"].values())


def test_two_demo_runs_give_the_same_state_digest(
    seed_demo: tuple[Path, str], tmp_path: Path
) -> None:
    """The stepped clock: every command lands on a known tick and the run ends on a known tick,
    so a second run (without the recorder, which only listens) streams the same states from
    tick 0 to the last, bit for bit."""
    first = json.loads((seed_demo[0] / "summary.json").read_text())["state_digest"]
    result = run_cli(
        ["demo", "--out", str(tmp_path), "--timeout", "600", "--no-record"], timeout_s=900
    )
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    second = json.loads((tmp_path / "summary.json").read_text())["state_digest"]
    assert second["first_tick"] == 0 and second["missing"] == 0 and second["conflicts"] == 0
    assert second == first


def test_free_running_demo_stays_available_and_says_it_is_not_reproducible(
    tmp_path: Path,
) -> None:
    result = run_cli(
        ["demo", "--vehicles", "1", "--clock", "lockstep", "--no-record", "--out", str(tmp_path)],
        timeout_s=900,
    )
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "not deterministic: lockstep clock" in result.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["ok"] and summary["clock"] == "lockstep" and summary["deterministic"] is False
