"""The randomised environment families, the tuning environments, the time limit an environment
gives and the sparse regime, as ``plumeswarm bench gsl`` flies them.

Expected values come from the environment files read with ``tomllib`` and from closed forms
(McMullen's σy, the straight-flight time, the wind's direction), never from the drawing code.
"""

from __future__ import annotations

import math
import tomllib
from typing import Any

import msgspec
import numpy as np
import pytest

from plume_service.from_scenario import field_from_scenario
from plume_service.statistics import time_averaged_widths, warmup_s
from plumeswarm.gsl.bench import make_options, specs_of
from plumeswarm.gsl.episode import EpisodeSpec, episode_scenario
from plumeswarm.gsl.registry import (
    GslError,
    environment_names,
    load_environment,
    tuning_environment_names,
)
from swarmbus.scenario import GSL_ENVIRONMENTS_DIR, GSL_TUNING_DIR, load_scenario

RUNS = 200
SEARCH_ALTITUDE_M = 10.0  # the protocol's flight altitude
SEARCH_SPEED_M_S = 2.0  # the oracle's straight flight (agents.behaviors.oracle)

# McMullen (1975), JAPCA 25(10):1057: σy = exp(I + J ln x + K (ln x)²), x in km, σ in m.
_MCMULLEN_Y = {
    "B": (5.058, 0.9024, -0.0096),
    "C": (4.651, 0.9181, -0.0076),
    "D": (4.230, 0.9222, -0.0087),
    "E": (3.922, 0.9222, -0.0064),
}


def mcmullen_sigma_y(stability: str, x_m: float) -> float:
    i, j, k = _MCMULLEN_Y[stability]
    ln_x = math.log(x_m / 1000.0)
    return math.exp(i + j * ln_x + k * ln_x * ln_x)


def ranges(name: str) -> dict[str, Any]:
    """The ``[randomise]`` table of a family file, read independently."""
    path = GSL_ENVIRONMENTS_DIR / f"{name}.toml"
    if not path.is_file():
        path = GSL_TUNING_DIR / f"{name}.toml"
    table: dict[str, Any] = tomllib.loads(path.read_text())["randomise"]
    return table


def episode(name: str, run: int, seed: int = 1000) -> tuple[Any, tuple[float, float]]:
    """Run ``run``'s episode scenario and its vehicle's start (x, y)."""
    scenario = episode_scenario(EpisodeSpec("random_walk", name, "ideal", run, seed))
    spawn = scenario.vehicles[0].spawn_enu_m
    return scenario, (spawn[0], spawn[1])


def downwind(from_deg: float) -> tuple[float, float]:
    """The unit vector the wind blows toward (ENU; from 0° = from the north, toward −y)."""
    a = math.radians(from_deg)
    return -math.sin(a), -math.cos(a)


def relative_start(scenario: Any, start: tuple[float, float]) -> tuple[float, float, float]:
    """(distance, along, across) of a start from the episode's first source in its mean wind."""
    src = scenario.plume.sources[0]
    dx, dy = start[0] - src.x_m, start[1] - src.y_m
    dw = downwind(scenario.wind.from_deg)
    along = dx * dw[0] + dy * dw[1]
    across = -dx * dw[1] + dy * dw[0]
    return math.hypot(dx, dy), along, across


@pytest.mark.parametrize("name", ["randomised", "tune_randomised"])
def test_draws_are_deterministic_per_seed_and_run_and_cover_the_files_ranges(name: str) -> None:
    r = ranges(name)
    rows = []
    for run in range(RUNS):
        scenario, _ = episode(name, run)
        again, _ = episode(name, run)
        assert scenario == again  # the same (seed, run): the same bits
        src = scenario.plume.sources[0]
        rows.append(
            (
                src.x_m,
                src.y_m,
                scenario.wind.from_deg,
                scenario.wind.speed_m_s,
                src.release_rate_g_s,
                src.release_height_m - SEARCH_ALTITUDE_M,
                scenario.plume.stability,
            )
        )
    assert episode(name, 0, seed=1001)[0] != episode(name, 0)[0]  # another seed, another draw
    keys = (
        "source_x_m",
        "source_y_m",
        "wind_from_deg",
        "wind_speed_m_s",
        "release_rate_g_s",
        "release_height_offset_m",
    )
    for i, key in enumerate(keys):
        values = np.array([row[i] for row in rows])
        lo, hi = r[key]
        assert values.min() >= lo and values.max() <= hi, key
        # 200 uniform draws come within 5 % of the range of each end (miss chance 2·0.95²⁰⁰)
        assert values.min() < lo + 0.05 * (hi - lo) and values.max() > hi - 0.05 * (hi - lo), key
    rates = np.array([row[4] for row in rows])
    lo, hi = r["release_rate_g_s"]
    # log-uniform: the median is the geometric mean of the ends (its error here ≈ 6 %)
    assert float(np.median(rates)) == pytest.approx(math.sqrt(lo * hi), rel=0.2)
    assert {row[6] for row in rows} == set(r["stability"]) == {"B", "C", "D", "E"}
    assert r["wind_speed_m_s"] == [2.0, 8.0] and r["wind_from_deg"] == [0.0, 360.0]
    assert r["release_height_offset_m"] == [-5.0, 5.0]


def test_starts_lie_in_the_documented_sector_and_crosswind_starts_outside_the_plume() -> None:
    r = ranges("randomised")
    lo, hi = r["start_distance_m"]
    crosswind = 0
    for run in range(RUNS):
        scenario, start = episode("randomised", run)
        distance, along, across = relative_start(scenario, start)
        bearing = abs(math.degrees(math.atan2(across, along)))
        assert lo - 1e-9 <= distance <= hi + 1e-9
        if bearing <= r["start_sector_deg"] + 1e-9:
            continue
        crosswind += 1
        c_lo, c_hi = r["crosswind_sector_deg"]
        assert c_lo - 1e-9 <= bearing <= c_hi + 1e-9, (run, bearing)
        # beside the time-averaged plume: more than 3 σy of its class at the start's distance
        # downwind (at least 1 m: beside the source itself)
        sigma = mcmullen_sigma_y(scenario.plume.stability, max(along, 1.0))
        assert abs(across) > 3.0 * sigma, (run, across, sigma)
    # a binomial fraction of 200 runs: within 4 standard errors
    p = r["crosswind_fraction"]
    assert abs(crosswind / RUNS - p) < 4.0 * math.sqrt(p * (1 - p) / RUNS)


def test_a_family_episodes_limit_is_its_multiple_of_the_straight_flight() -> None:
    multiple = ranges("randomised")["time_limit_multiple"]
    opts = make_options(["surge_cast"], ["randomised", "meander_low"], ["ideal"], runs=5, seed=1000)
    specs = specs_of(opts)
    limits = set()
    for spec in specs:
        if spec.environment == "meander_low":
            assert spec.time_limit_s == 300.0  # a fixed environment keeps the default
            continue
        scenario, start = episode("randomised", spec.run)
        src = scenario.plume.sources[0]
        distance = math.hypot(start[0] - src.x_m, start[1] - src.y_m)
        assert spec.time_limit_s == pytest.approx(multiple * distance / SEARCH_SPEED_M_S)
        limits.add(spec.time_limit_s)
    assert len(limits) == 5  # each run its own
    auto = specs_of(make_options([], ["meander_low"], ["ideal"], runs=3, time_limit_s="auto"))
    for spec in auto:
        scenario, start = episode("meander_low", spec.run, seed=0)
        distance = math.hypot(start[0], start[1])  # meander_low's source is at the origin
        assert spec.time_limit_s == pytest.approx(10.0 * distance / SEARCH_SPEED_M_S)
    with pytest.raises(GslError, match="--time-limit 'soon': seconds"):
        make_options([], ["meander_low"], ["ideal"], time_limit_s="soon")


def _runs_with_each_class() -> list[int]:
    found: dict[str, int] = {}
    for run in range(50):
        found.setdefault(episode("randomised", run)[0].plume.stability, run)
    return [found[c] for c in sorted(found)]


@pytest.mark.parametrize("run", _runs_with_each_class())
def test_a_drawn_plumes_time_average_has_its_classs_sigma_y_at_50_m(run: int) -> None:
    scenario, _ = episode("randomised", run)
    src = scenario.plume.sources[0]
    field = field_from_scenario(scenario)
    # 480 s sampled every 2 s after the warm-up (a slow meander, T_L up to ≈ 20 s at 2 m/s, needs
    # the length: 240 s gave 0.84 of class B once): the crosswind second moment of the average
    (width,) = time_averaged_widths(
        field,
        (src.x_m, src.y_m, src.release_height_m),
        downwind(scenario.wind.from_deg),
        (50.0,),
        warmup_s(scenario),
        480.0,
        every_s=2.0,
        half_width_m=40.0,
        spacing_m=1.0,
    )
    expected = mcmullen_sigma_y(scenario.plume.stability, 50.0)
    assert width.sigma_y_m == pytest.approx(expected, rel=0.2), (scenario.plume.stability, width)


def test_tuning_environments_are_apart_from_the_published_ones() -> None:
    tuning = tuning_environment_names()
    assert {"tune_randomised", "tune_north_c", "tune_steady"} <= set(tuning)
    assert not set(tuning) & set(environment_names())  # never in `--environments all`
    for name in tuning:
        env = load_environment(name)
        assert env.path.parent == GSL_TUNING_DIR
        assert load_environment(f"gsl/tuning/{name}").path == env.path
        scenario = load_scenario(GSL_TUNING_DIR / f"{name}.toml")
        if name == "tune_steady":  # the steady Gaussian: its class's σy and σz by definition
            assert scenario.plume.model == "gaussian" and scenario.wind.model == "steady"
        elif name == "tune_farrell":  # Farrell et al.'s published filaments in another wind
            reference = load_scenario(GSL_ENVIRONMENTS_DIR / "farrell2002_reference.toml")
            assert scenario.plume.calibration is None and scenario.wind.model == "field"
            filament = msgspec.structs.replace(reference.plume.filament, max_age_s=200.0)
            assert scenario.plume.filament == filament
            assert scenario.wind.speed_m_s != reference.wind.speed_m_s
            assert scenario.wind.from_deg != reference.wind.from_deg
            assert scenario.wind.meander.resolved() != reference.wind.meander.resolved()
            assert scenario.plume.sources != reference.plume.sources
        else:  # a time-dependent plume whose time average is calibrated to its class
            assert scenario.plume.calibration is not None
    # the tuning family draws its sources where the test family never does
    test, tune = ranges("randomised"), ranges("tune_randomised")
    assert test["source_x_m"][1] < tune["source_x_m"][0]


def test_a_bad_randomise_table_is_one_line(tmp_path: Any) -> None:
    text = (GSL_ENVIRONMENTS_DIR / "randomised.toml").read_text()
    bad = tmp_path / "bad.toml"
    bad.write_text(text.replace("wind_speed_m_s = [2.0, 8.0]", "wind_speed_m_s = [8.0, 2.0]"))
    with pytest.raises(GslError, match=r"randomise\.wind_speed_m_s = \[8\.0, 2\.0\]: low above"):
        load_environment(str(bad))
    bad.write_text(text.replace("stability = [", "stabilty = ["))
    with pytest.raises(GslError, match=r"randomise\.stabilty: unknown key; valid: source_x_m"):
        load_environment(str(bad))


def test_sparse_far_is_hit_in_fewer_than_half_of_the_seconds_on_the_axis_at_80_m() -> None:
    # another realisation (seed 7) of 300 s at 10 Hz, on the axis at the release height:
    # meander_high's atmosphere with 1 % of its release (docs/gsl.md: 0.23 over 600 s)
    scenario = load_environment("sparse_far").scenario
    world = msgspec.structs.replace(scenario.world, seed=7)
    field = field_from_scenario(msgspec.structs.replace(scenario, world=world))
    start = warmup_s(scenario)
    point = np.array([[80.0, 0.0, 10.0]])
    values = np.array([field.concentration(point, start + k * 0.1)[0] for k in range(3000)])
    windows = (values >= 0.001).reshape(300, 10).any(axis=1)
    assert 0.05 < windows.mean() < 0.5
    assert (values >= 0.001).mean() < 0.1
