"""``plumeswarm plume series``: the field over time at points, without starting any process."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from matplotlib.image import imread

from swarmbus.scenario import load_scenario, resolve_scenario_path
from tests.support.procs import run_cli


def _series(*args: str) -> dict[str, list]:
    res = run_cli(["plume", "series", *args, "--format", "json"])
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_filament_series_is_intermittent_and_repeats_bit_for_bit() -> None:
    args = ("filament", "--point", "20", "0", "5", "--point", "10", "0", "5")
    out = _series(*args, "--seconds", "30", "--every", "0.05")
    assert out["points"] == [[20.0, 0.0, 5.0], [10.0, 0.0, 5.0]]
    assert len(out["t"]) == 601 and out["t"][1] == 0.05
    rows = out["values_g_m3"]
    assert len(rows) == 601 and all(len(r) == 2 for r in rows)
    at_20 = [r[0] for r in rows]
    hits = sum(v > 0.0 for v in at_20)
    assert 0 < hits < 0.9 * len(at_20)  # bursts and silences
    assert _series(*args, "--seconds", "30", "--every", "0.05") == out


def test_gaussian_series_repeats_the_steady_value() -> None:
    out = _series("novak2018", "--point", "30", "0", "10", "--seconds", "1", "--every", "0.5")
    (a,), (b,), (c,) = out["values_g_m3"]
    assert a == b == c > 0.0


def test_series_errors_name_the_option() -> None:
    cases = {
        ("--seconds", "1", "--every", "0"): "--every must be a positive number",
        ("--seconds", "-1", "--every", "1"): "--seconds must be a number >= 0",
        ("--seconds", "1e9", "--every", "1e-3"): "exceed 1000000",
        ("--seconds", "1", "--every", "nan"): "--every must be a positive number",
    }
    for extra, message in cases.items():
        res = run_cli(["plume", "series", "novak2018", "--point", "1", "2", "3", *extra])
        assert res.returncode != 0 and message in res.stderr, res.stderr
        assert "Traceback" not in res.stderr
    res = run_cli(["plume", "series", "nosuch", "--point", "1", "2", "3", "--seconds", "1"])
    assert res.returncode != 0 and "Traceback" not in res.stderr


def test_filament_scenario_samples_at_20_hz_or_more() -> None:
    scenario = load_scenario(resolve_scenario_path("filament"))
    assert scenario.plume.model == "filament" and scenario.wind.model == "meander"
    assert scenario.time.control_hz / scenario.sensor.period_ticks >= 20.0
    assert len(scenario.vehicles) == 3
    assert math.isclose(scenario.plume.filament.initial_radius_m**2, 0.001, rel_tol=1e-3)


def test_plume_sample_at_a_time_is_the_series_value_then() -> None:
    out = _series("filament", "--point", "20", "0", "5", "--seconds", "40", "--every", "0.05")
    values = [row[0] for row in out["values_g_m3"]]
    k = max(range(len(values)), key=values.__getitem__)  # the strongest burst
    t = out["t"][k]
    args = ["plume", "sample", "--scenario", "filament", "--time", repr(t), "--format", "json"]
    res = run_cli([*args, "20", "0", "5"])
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)[0]["concentration_g_m3"] == values[k] > 0.0


def test_plume_plot_of_a_filament_scenario_at_a_time(tmp_path: Path) -> None:
    res = run_cli(
        ["plume", "plot", "--scenario", "filament", "--time", "40", "--out", str(tmp_path)]
    )
    assert res.returncode == 0, res.stderr
    pixels = imread(tmp_path / "concentration_plan.png")
    assert np.var(pixels[..., :3]) > 1e-3, "the plan view is blank"
    res = run_cli(
        ["plume", "plot", "--scenario", "filament", "--time", "0", "--out", str(tmp_path)]
    )
    assert res.returncode != 0 and "pick a later --time" in res.stderr
    assert "Traceback" not in res.stderr
