"""The mass-balance survey: its integrator against the Gaussian plume's own integral, its
estimate in the steady environment flown by the kinematic runner and by the Aerosonde, the
published table reproduced, and its refusals (docs/survey.md)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import math
import tomllib
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.plume_formula import downwind_unit, gaussian_plume_g_m3, plume_frame
from plumeswarm.gsl.registry import load_environment
from plumeswarm.survey import CurtainPlan, SurveyError, SurveyReading, estimate_flux
from plumeswarm.survey.bench import (
    EnvironmentRow,
    SurveyOptions,
    command_line,
    survey_run,
    table_lines,
)
from plumeswarm.survey.flight import Racetrack, fly_survey, leg_order
from plumeswarm.survey.flux import vertical_integral
from plumeswarm.survey.pattern import model_coverage, plan_for_scenario
from plumeswarm.survey.plane import fly_plane_survey
from tests.support.procs import REPO, run_cli

SOURCE = (30.0, -20.0)
WIND_FROM_DEG = 225.0  # toward the north-east: the curtain is not along a grid axis
WIND_M_S = 6.0
RELEASE_G_S = 10.0
DISTANCE_M = 50.0


def curtain_readings(
    curves_name: str,
    release_height_m: float,
    heights_m: np.ndarray,
    half_width_m: float,
    dy_m: float = 0.1,
) -> tuple[CurtainPlan, list[SurveyReading]]:
    """The closed-form plume read on a dense curtain, the wind measured exactly."""
    plan = CurtainPlan(SOURCE, WIND_FROM_DEG, DISTANCE_M, tuple(heights_m), half_width_m)
    curves = dispersion_curves(curves_name, "D")
    ux, uy = downwind_unit(WIND_FROM_DEG)
    wind = (WIND_M_S * ux, WIND_M_S * uy)
    y = np.arange(-half_width_m, half_width_m + dy_m / 2, dy_m)
    readings, t = [], 0.0
    for z in heights_m:
        points = [plan.enu(0.0, float(v), float(z)) for v in y]
        e = np.array([p[0] for p in points])
        n = np.array([p[1] for p in points])
        x_down, y_cross = plume_frame(e, n, SOURCE[0], SOURCE[1], WIND_FROM_DEG)
        c = gaussian_plume_g_m3(
            x_down, y_cross, np.full(e.shape, z), RELEASE_G_S, WIND_M_S, release_height_m, curves
        )
        for p, value in zip(points, c, strict=True):
            readings.append(SurveyReading(t, p, float(value), wind))
            t += 0.01
        t += 1.0  # a turn between legs: the passes are separate runs
    return plan, readings


@pytest.mark.parametrize(
    ("curves_name", "release_height_m"), [("novak2018", 10.0), ("mcmullen", 2.0)]
)
def test_the_flux_of_the_closed_form_plume_through_a_dense_curtain_is_the_release_rate(
    curves_name: str, release_height_m: float
) -> None:
    """C = Q/(2π u σy σz)·e^(−y²/2σy²)·[e^(−(z−H)²/2σz²) + e^(−(z+H)²/2σz²)]: over y the
    Gaussian integrates to √(2π)σy, over z ≥ 0 the reflected pair to √(2π)σz (the image's half
    below ground is the source's half above it), so u·∫∫ C dy dz = Q — the ground reflection
    included (a release at 2 m puts much of the plume against the ground)."""
    curves = dispersion_curves(curves_name, "D")
    sigma_y, sigma_z = (float(s[0]) for s in curves.sigmas(np.array([DISTANCE_M])))
    heights = np.arange(0.5, release_height_m + 8.0 * sigma_z, 0.5)
    plan, readings = curtain_readings(
        curves_name, release_height_m, heights, 8.0 * sigma_y, dy_m=0.2
    )
    estimate = estimate_flux(readings, plan, background_g_m3=0.0)
    assert estimate.release_rate_g_s == pytest.approx(RELEASE_G_S, rel=0.005)
    assert estimate.wind_normal_m_s == pytest.approx(WIND_M_S, rel=1e-12)
    assert estimate.passes == (1,) * len(heights)


def test_a_curtain_that_cuts_the_plume_integrates_the_closed_form_share_that_crosses_it() -> None:
    """Legs over ±1 σy between H − σz and H + σz: the flown part of the integral is Q times
    erf(1/√2) crosswind times ½[erf(1/√2) + erf(1/√2) + erf((2H + σz)/√2σz) −
    erf((2H − σz)/√2σz)] vertically (the source's and the image's shares of the band)."""
    h = 10.0
    curves = dispersion_curves("mcmullen", "D")
    sigma_y, sigma_z = (float(s[0]) for s in curves.sigmas(np.array([DISTANCE_M])))
    heights = np.linspace(h - sigma_z, h + sigma_z, 81)
    plan, readings = curtain_readings("mcmullen", h, heights, sigma_y, dy_m=0.02)
    estimate = estimate_flux(readings, plan, background_g_m3=0.0)
    _, flown = vertical_integral(estimate.heights_m, estimate.line_integrals_g_m2)
    r = math.sqrt(0.5)
    across = math.erf(r)
    vertical = 0.5 * (
        2.0 * math.erf(r) + math.erf((2 * h + sigma_z) / (math.sqrt(2) * sigma_z))
        - math.erf((2 * h - sigma_z) / (math.sqrt(2) * sigma_z))
    )  # fmt: skip
    share = across * vertical
    assert WIND_M_S * flown == pytest.approx(RELEASE_G_S * share, rel=0.002)
    assert model_coverage(plan, sigma_y, sigma_z, h) == pytest.approx(share, rel=1e-9)


def test_the_survey_estimates_the_steady_gaussian_release_within_30_percent() -> None:
    """Flown by the kinematic runner at 18 m/s over the planned curtain (50 m downwind, legs
    from 2 m every σz, ±4 σy), read through the anemometer's noise."""
    scenario = load_environment("steady_gaussian").scenario
    plan = plan_for_scenario(scenario)
    readings = fly_survey(scenario, plan)
    estimate = estimate_flux(readings, plan)
    truth = scenario.plume.sources[0].release_rate_g_s
    assert abs(estimate.release_rate_g_s - truth) <= 0.3 * truth
    assert estimate.passes == (1,) * len(plan.heights_m)
    assert 5.9 < estimate.wind_normal_m_s < 6.1


def _toml(path: Path) -> dict[str, Any]:
    with path.open("rb") as f:
        return tomllib.load(f)


def test_the_aerosonde_estimates_the_steady_gaussian_release_within_30_percent() -> None:
    """One sweep flown by the plane (its autopilot and physics in the fused runner). The true
    rate and the wind are read from the environment's file, the cruise airspeed from the
    Aerosonde's: a plane at 25 m/s airspeed crabbing across a 6 m/s wind normal to its track
    makes √(25² − 6²) = 24.3 m/s along it, 1.21 m between readings at 20 Hz (the kinematic
    runner's point makes 18 m/s, 0.9 m)."""
    env = _toml(REPO / "swarmbus" / "scenarios" / "gsl" / "steady_gaussian.toml")
    airframe = _toml(REPO / "swarmbus" / "vehicles" / "aerosonde.toml")
    truth = env["plume"]["sources"][0]["release_rate_g_s"]
    wind = env["wind"]["speed_m_s"]
    cruise = airframe["fixed_wing"]["params"]["FW_AIRSPD_TRIM"]
    scenario = load_environment("steady_gaussian").scenario
    plan = plan_for_scenario(scenario)
    flight = fly_plane_survey(scenario, plan, repeats=1, sample_hz=20.0)
    estimate = estimate_flux(flight.readings, plan, height_tolerance_m=flight.height_tolerance_m)
    assert abs(estimate.release_rate_g_s - truth) <= 0.3 * truth
    assert estimate.passes == (1,) * len(plan.heights_m)
    assert wind - 0.1 < estimate.wind_normal_m_s < wind + 0.1
    on_legs = [
        (a, b)
        for a, b in itertools.pairwise(flight.readings)
        if abs(plan.curtain_frame(*a.position_enu_m[:2])[1]) <= plan.half_width_m
        and abs(plan.curtain_frame(*a.position_enu_m[:2])[0]) < 50.0  # not the straight back
    ]
    assert len(on_legs) >= 5 * len(plan.heights_m)
    step = math.sqrt(cruise**2 - wind**2) / 20.0
    for a, b in on_legs:
        assert math.dist(a.position_enu_m, b.position_enu_m) == pytest.approx(step, rel=0.05)
        assert abs(plan.curtain_frame(*a.position_enu_m[:2])[0]) < 5.0


def test_the_published_tables_first_run_is_reproduced_bit_for_bit() -> None:
    """results/survey/survey.json's first environment, run 0, flown again with the options
    the JSON records: the same estimate and errors, to the last bit."""
    document = json.loads((REPO / "results" / "survey" / "survey.json").read_text())
    options = msgspec.convert(document["options"], SurveyOptions)
    row = document["rows"][0]
    published = row["runs"][0]
    base = load_environment(row["environment"]).scenario
    again = survey_run(base, options, 0)
    assert again.estimate is not None
    assert again.estimate.release_rate_g_s == published["estimate"]["release_rate_g_s"]
    assert list(again.sweep_errors_pct) == published["sweep_errors_pct"]
    assert again.flight_s == published["flight_s"]


def test_the_racetrack_is_flown_at_constant_speed_and_crosses_every_leg() -> None:
    """Consecutive readings are v·dt apart horizontally (ground speed; a chord of a turn is a
    hair shorter than its arc); each planned height has a pass across its whole leg a sweep."""
    scenario = load_environment("steady_gaussian").scenario
    plan = plan_for_scenario(scenario)
    readings = fly_survey(scenario, plan, speed_m_s=18.0, repeats=2, sample_hz=20.0)
    steps = [
        math.dist(a.position_enu_m[:2], b.position_enu_m[:2])
        for a, b in itertools.pairwise(readings)
    ]
    assert max(steps) <= 0.9 + 1e-6
    assert min(steps) >= 0.89
    legs = list(range(len(plan.heights_m)))
    assert leg_order(plan, 2) == legs + legs[::-1]
    estimate = estimate_flux(readings, plan)
    assert estimate.passes == (2,) * len(plan.heights_m)
    path = Racetrack(plan, (0, 1), 57.0)
    assert path.at(0.0) == (0.0, -plan.half_width_m, plan.heights_m[0])
    end = path.at(path.length_m)
    assert end[0] == pytest.approx(0.0, abs=1e-9)
    assert end[1] == pytest.approx(plan.half_width_m)
    assert end[2] == plan.heights_m[1]


def test_a_curtain_that_misses_the_plume_is_refused_not_zero() -> None:
    """The same curtain moved 200 m crosswind of the plume reads clean air everywhere."""
    scenario = load_environment("steady_gaussian").scenario
    plan = plan_for_scenario(scenario)
    aside = dataclasses.replace(
        plan, source_enu_m=(plan.source_enu_m[0], plan.source_enu_m[1] + 200.0)
    )
    readings = fly_survey(scenario, aside)
    with pytest.raises(SurveyError, match="curtain misses the plume") as info:
        estimate_flux(readings, aside)
    assert info.value.field == "curtain"


def test_a_survey_at_one_height_is_refused() -> None:
    scenario = load_environment("steady_gaussian").scenario
    plan = plan_for_scenario(scenario)
    one = dataclasses.replace(plan, heights_m=plan.heights_m[:1])
    readings = fly_survey(scenario, one)
    with pytest.raises(SurveyError, match="at 2 heights or more") as info:
        estimate_flux(readings, one)
    assert info.value.field == "legs"


def test_bench_survey_refuses_a_bad_distance_in_one_line(tmp_path: Path) -> None:
    done = run_cli(["bench", "survey", "--distance", "-5", "--runs", "1", "--out", str(tmp_path)])
    assert done.returncode == 2
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1
    assert "distance_m" in lines[0] and "-5" in lines[0]
    assert "Traceback" not in done.stderr


def test_bench_survey_writes_the_table_under_its_command_and_every_run(tmp_path: Path) -> None:
    done = run_cli(
        ["bench", "survey", "--environments", "steady_gaussian", "--runs", "2", "--dynamics",
         "kinematic", "--out", str(tmp_path)]
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    table = (tmp_path / "survey.md").read_text().splitlines()
    assert table[0].startswith("`plumeswarm bench survey --environments steady_gaussian --runs 2")
    assert table[4].startswith("| `steady_gaussian` | 2/2 | 10 |")
    document = json.loads((tmp_path / "survey.json").read_text())
    (row,) = document["rows"]
    assert [r["seed"] for r in row["runs"]] == [0, 1]
    assert abs(row["summary"]["mean_error_pct"]) < 30.0


def test_the_published_tables_are_the_benchs_own_rendering_of_its_json() -> None:
    """Every table in docs/survey.md is what ``table_lines`` makes of the ``survey.json`` the
    same command wrote (results/survey*/), and is that command's ``survey.md``: no number was
    edited by hand."""
    page = (REPO / "docs" / "survey.md").read_text()
    documents = sorted((REPO / "results").glob("survey*/survey.json"))
    assert len(documents) >= 2
    for path in documents:
        document = json.loads(path.read_text())
        options = msgspec.convert(document["options"], SurveyOptions)
        rows = [msgspec.convert(r, EnvironmentRow) for r in document["rows"]]
        assert document["command"] == command_line(options)
        table = "\n".join(table_lines(options, rows))
        assert table in page, f"{path.parent.name}: the page's table differs from its JSON"
        assert (path.parent / "survey.md").read_text() == table + "\n"


def test_a_first_order_sensors_lag_is_undone_from_the_response_it_still_owes() -> None:
    """The dense curtain's readings through a first-order lag (τ = 1.3 s, the PID preset's;
    updated exactly for each 0.01 s step, its state carried over the turns): at 20 m/s the
    lag moves 26 m of response along a leg that reaches 32 m past the axis, and the part past
    the leg's end is lost unless it is added back."""
    curves = dispersion_curves("novak2018", "D")
    sigma_y, sigma_z = (float(s[0]) for s in curves.sigmas(np.array([DISTANCE_M])))
    heights = np.arange(0.5, 10.0 + 8.0 * sigma_z, 0.5)
    plan, readings = curtain_readings("novak2018", 10.0, heights, 8.0 * sigma_y, dy_m=0.2)
    tau, lagged, m, t = 1.3, [], 0.0, readings[0].sim_time_s
    for r in readings:
        m *= math.exp(-max(0.0, r.sim_time_s - t - 0.01) / tau)  # clean air in a turn
        t = r.sim_time_s
        m += (r.concentration_g_m3 - m) * (1.0 - math.exp(-0.01 / tau))
        lagged.append(dataclasses.replace(r, concentration_g_m3=m))
    raw = estimate_flux(lagged, plan, background_g_m3=0.0)
    undone = estimate_flux(lagged, plan, background_g_m3=0.0, sensor_lag_s=tau)
    assert raw.release_rate_g_s < 0.9 * RELEASE_G_S
    assert undone.release_rate_g_s == pytest.approx(RELEASE_G_S, rel=0.01)
