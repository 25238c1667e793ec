"""``plumeswarm demo`` end to end: the real stack flies the seed scenario and lands."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from matplotlib.image import imread

from deploy.launcher import missing_roles
from deploy.recording.report import READING_COLUMNS, TRACK_COLUMNS
from tests.procs import run_cli
from tests.test_report import PNGS

pytestmark = pytest.mark.skipif(
    bool(missing_roles(["plume", "physics", "autopilot"])),
    reason="roles not built yet: " + ", ".join(missing_roles(["plume", "physics", "autopilot"])),
)


def test_demo_flies_the_seed_scenario_and_writes_the_summary(tmp_path: Path) -> None:
    result = run_cli(["demo", "--out", str(tmp_path), "--timeout", "600"], timeout_s=900)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert "every vehicle completed its mission and landed" in result.stdout
    assert "reported" in result.stdout and "model" in result.stdout
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["ok"] and summary["scenario"]["vehicles"] == 3
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
