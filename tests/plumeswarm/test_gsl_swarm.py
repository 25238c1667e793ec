"""``bench gsl --vehicles N --radio ...``: the options reach every episode and the command line;
a swarm's starts, its columns and its speed-up."""

from __future__ import annotations

import csv
import itertools
import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from plumeswarm.gsl.bench import (
    GslError,
    command_line,
    make_options,
    parse_radio,
    runs_csv,
    specs_of,
)
from plumeswarm.gsl.episode import (
    EpisodeSpec,
    Outcome,
    Tally,
    episode_scenario,
    episode_starts,
    start_point,
)
from plumeswarm.gsl.registry import load_environment
from plumeswarm.gsl.stats import speedup
from swarmbus.radio import RadioSpec

REPO = Path(__file__).resolve().parents[2]


def test_radio_text_becomes_the_radio_sections_fields() -> None:
    assert parse_radio("loss=0.2, latency=12,range=80,bytes=64") == (
        ("radio.loss", 0.2),
        ("radio.latency_ticks", 12),
        ("radio.range_m", 80.0),
        ("radio.max_message_bytes", 64),
    )
    assert parse_radio("") == ()
    with pytest.raises(GslError, match=r"'lost=0\.2'.*range, loss, latency, bytes"):
        parse_radio("lost=0.2")
    with pytest.raises(GslError, match=r"'x' is not a number"):
        parse_radio("latency=x")


def test_vehicles_and_radio_reach_every_episodes_scenario() -> None:
    opts = make_options(
        ["surge_cast"], ["steady_gaussian"], ["ideal"], runs=2, vehicles=4,
        radio="loss=0.5,latency=3",
    )  # fmt: skip
    specs = specs_of(opts)
    assert len(specs) == 3 * 2  # random_walk, surge_cast, oracle
    for spec in specs:
        scenario = episode_scenario(spec)
        assert len(scenario.vehicles) == 4
        assert scenario.radio == RadioSpec(loss=0.5, latency_ticks=3)
    assert "--vehicles 4 --radio loss=0.5,latency=3" in command_line(opts)
    with pytest.raises(GslError, match=r"radio\.loss"):
        make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], radio="loss=2")


def test_without_the_options_each_algorithm_flies_its_own_vehicles_on_a_perfect_link() -> None:
    opts = make_options(["gradient_swarm", "surge_cast"], ["steady_gaussian"], ["ideal"], runs=1)
    counts = {s.algorithm: len(episode_scenario(s).vehicles) for s in specs_of(opts)}
    assert counts == {"random_walk": 1, "gradient_swarm": 3, "surge_cast": 1, "oracle": 1}
    assert all(episode_scenario(s).radio.perfect for s in specs_of(opts))
    assert "--vehicles" not in command_line(opts) and "--radio" not in command_line(opts)


def test_a_swarm_starts_on_a_crosswind_line_centred_on_the_runs_start() -> None:
    """Every environment's wind blows from 270° (toward +x): crosswind is ±y. The line is
    across the wind, its points ``spacing`` apart, its centre the one-vehicle start."""
    for spacing in (4.0, 2.5):
        spec = EpisodeSpec("coop_declare", "meander_low", "ideal", 3, 1000, vehicles=5,
                           start_spacing_m=spacing)  # fmt: skip
        base = load_environment("meander_low").scenario
        assert base.wind.from_deg == 270.0
        sx, sy = start_point(base, 1000, 3)
        starts = episode_starts(base, spec, 5)
        assert [p[0] for p in starts] == pytest.approx([sx] * 5, abs=1e-9)
        ys = sorted(p[1] for p in starts)
        assert [b - a for a, b in itertools.pairwise(ys)] == pytest.approx([spacing] * 4)
        assert sum(ys) / 5 == pytest.approx(sy)
    # one vehicle: the run's start; the algorithm's own spacing; spacing 0: the 2 m circle
    one = EpisodeSpec("coop_declare", "meander_low", "ideal", 3, 1000, vehicles=1)
    assert episode_starts(base, one, 1) == [[sx, sy, 10.0]]
    assert EpisodeSpec("coop_declare", "meander_low", "ideal", 3, 1000).spacing_m() == 4.0
    for spec in (
        EpisodeSpec("gradient_swarm", "meander_low", "ideal", 3, 1000, vehicles=3),
        EpisodeSpec("coop_declare", "meander_low", "ideal", 3, 1000, vehicles=3,
                    start_spacing_m=0.0),
    ):  # fmt: skip
        for p in episode_starts(base, spec, 3):
            assert math.hypot(p[0] - sx, p[1] - sy) == pytest.approx(2.0)


def test_vehicles_counts_are_cells_and_the_swarm_columns_appear_only_for_a_swarm() -> None:
    opts = make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], runs=2, vehicles="1,3",
                        spacing=5.0)  # fmt: skip
    assert opts.vehicles == (1, 3) and opts.swarm
    assert [(s.algorithm, s.vehicles, s.run) for s in specs_of(opts)][:4] == [
        ("random_walk", 1, 0), ("random_walk", 1, 1), ("random_walk", 3, 0), ("random_walk", 3, 1)
    ]  # fmt: skip
    assert all(s.start_spacing_m == 5.0 for s in specs_of(opts))
    assert "--vehicles 1,3 --spacing 5" in command_line(opts)
    assert not make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], vehicles=1).swarm
    for bad in ("0", "1,x", "65"):
        with pytest.raises(GslError, match=r"--vehicles .*1 to 64"):
            make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], vehicles=bad)
    spec = EpisodeSpec("a", "steady_gaussian", "ideal", 0, 0, vehicles=2)
    outcome = Outcome(spec, True, 10.0, 5.0, 50.0, 0.5, 1.0, True, (0.0, 0.0),
                      closest_approach_m=1.5, total_path_m=10.0, nearest_member_m=0.5)  # fmt: skip
    plain, swarm = runs_csv([outcome]).splitlines(), runs_csv([outcome], swarm=True).splitlines()
    assert swarm[0] == plain[0] + ",vehicles,closest_approach_m,total_path_m,nearest_member_m"
    assert swarm[1] == plain[1] + ",2,1.5000,10.0000,0.5000"


def test_the_tally_counts_the_closest_approach_and_the_swarms_total_path() -> None:
    spec = EpisodeSpec("a", "steady_gaussian", "ideal", 0, 0, vehicles=3)
    tally = Tally(spec, 3, 0.05, 0.0, (0.0, 0.0), (100.0, 0.0))
    tally.observe(0.0, [(0.0, 0.0, 10.0), (0.0, 4.0, 10.0), (0.0, -4.0, 10.0)])
    tally.observe(0.05, [(3.0, 0.0, 10.0), (0.0, 1.0, 10.0), (0.0, -4.0, 12.0)])
    outcome = tally.outcome(0.05, None)
    assert outcome.closest_approach_m == pytest.approx(math.hypot(3.0, 1.0))
    assert outcome.total_path_m == pytest.approx(3.0 + 3.0 + 0.0)  # horizontal path
    assert outcome.path_length_m == pytest.approx(2.0)  # per vehicle, as before
    assert outcome.nearest_member_m == pytest.approx(97.0)  # the first vehicle at (3, 0)
    assert outcome.min_distance_m == pytest.approx(math.dist((1.0, -1.0), (100.0, 0.0)))


def test_the_speed_up_is_the_ratio_of_medians_with_a_paired_bootstrap_interval() -> None:
    single = [100.0, 120.0, 130.0, 140.0, 150.0]
    point, ci = speedup(single, [t / 2.0 for t in single])
    assert point == pytest.approx(2.0) and ci == pytest.approx((2.0, 2.0))  # every pair: 2
    point, ci = speedup(single, [50.0, 60.0, 70.0, 65.0, 80.0])
    assert point == pytest.approx(130.0 / 65.0)
    assert ci is not None and ci[0] <= point <= ci[1]
    # a resample's ratio lies between the pairs' extreme ratios
    ratios = [a / b for a, b in zip(single, [50.0, 60.0, 70.0, 65.0, 80.0], strict=True)]
    assert min(ratios) <= ci[0] and ci[1] <= max(single) / min(50.0, 60.0, 70.0, 65.0, 80.0)
    assert speedup([100.0, 90.0], [50.0, 45.0]) == (pytest.approx(2.0), None)


def test_the_command_line_flies_the_swarm_options(tmp_path: Path) -> None:
    """``--vehicles``, ``--spacing`` and ``--radio`` reach the episodes through the command."""
    args = ["--algorithms", "coop_declare", "--environments", "steady_gaussian", "--sensors"]
    args += ["ideal", "--runs", "1", "--seed", "1000", "--time-limit", "5", "--jobs", "1"]
    args += ["--vehicles", "1,3", "--spacing", "3", "--radio", "loss=0.5"]
    res = subprocess.run(
        [sys.executable, "-m", "plumeswarm", "bench", "gsl", *args, "--out", str(tmp_path)],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    rows = json.loads((tmp_path / "gsl.json").read_text())
    assert [(r["algorithm"], r["vehicles"]) for r in rows][:4] == [
        ("random_walk", 1), ("random_walk", 3), ("coop_declare", 1), ("coop_declare", 3)
    ]  # fmt: skip
    assert all(r["radio"] == {"radio.loss": 0.5} for r in rows)
    assert "--vehicles 1,3 --spacing 3 --radio loss=0.5" in (tmp_path / "gsl.md").read_text()
    lines = (tmp_path / "runs.csv").read_text().splitlines()
    assert lines[0].endswith(",vehicles,closest_approach_m,total_path_m,nearest_member_m")
    # the three members start 3 m apart across the wind: nothing closer at the start
    swarm = [r for r in csv.DictReader(lines) if r["vehicles"] == "3"]
    assert swarm and all(float(r["closest_approach_m"]) <= 3.0 + 1e-3 for r in swarm)
