"""``bench gsl --vehicles N --radio ...``: the options reach every episode and the command line;
a swarm's starts, its columns and its speed-up."""

from __future__ import annotations

import csv
import itertools
import json
import math
import subprocess
import sys
from collections import Counter
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from agents.behavior import ignores_peers
from plumeswarm.gsl.bench import (
    GslError,
    command_line,
    make_options,
    parse_radio,
    rows_of,
    runs_csv,
    specs_of,
)
from plumeswarm.gsl.episode import (
    EpisodeSpec,
    Outcome,
    Tally,
    episode_scenario,
    episode_starts,
    run_episode,
    start_point,
)
from plumeswarm.gsl.registry import BUILTIN_ALGORITHMS, load_environment
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
    assert swarm[0] == plain[0] + ",vehicles,radio,closest_approach_m,total_path_m,nearest_member_m"
    assert swarm[1] == plain[1] + ",2,perfect,1.5000,10.0000,0.5000"


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
    assert lines[0].endswith(",vehicles,radio,closest_approach_m,total_path_m,nearest_member_m")
    # the three members start 3 m apart across the wind: nothing closer at the start
    assert {r["radio"] for r in csv.DictReader(lines)} == {"loss=0.5"}
    swarm = [r for r in csv.DictReader(lines) if r["vehicles"] == "3"]
    assert swarm and all(float(r["closest_approach_m"]) <= 3.0 + 1e-3 for r in swarm)


LOSS_05_1S = (("radio.loss", 0.5), ("radio.latency_ticks", 20))


def test_several_radios_are_cells_and_a_cell_no_radio_changes_is_flown_once() -> None:
    """``--radio perfect/…/…``: each setting its own cells for a swarm that hears its peers
    (one that talks, or one that reads their states or readings: gradient_swarm); one
    vehicle, or a behaviour that ignores its peers, flies on the first setting only."""
    opts = make_options(
        ["surge_cast", "coop_declare", "gradient_swarm"], ["steady_gaussian"], ["ideal"],
        runs=2, vehicles="1,3", radio="perfect/loss=0.5,latency=20/loss=0.2",
    )  # fmt: skip
    cells = Counter((s.algorithm, s.vehicles, s.overrides) for s in specs_of(opts))
    loss_02 = (("radio.loss", 0.2),)
    single = {(a, n, ()): 2 for a in ("random_walk", "surge_cast", "oracle") for n in (1, 3)}
    heard = {
        (a, 3, radio): 2
        for a in ("coop_declare", "gradient_swarm")
        for radio in ((), LOSS_05_1S, loss_02)
    }
    expected: dict[Any, int] = {}
    expected.update(single)
    expected.update({("coop_declare", 1, ()): 2, ("gradient_swarm", 1, ()): 2})
    expected.update(heard)
    assert cells == expected
    assert "--radio perfect/loss=0.5,latency=20/loss=0.2" in command_line(opts)
    with pytest.raises(GslError, match="given twice"):
        make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], radio="loss=0.2/loss=0.2")
    with pytest.raises(GslError, match="not a number"):
        make_options(["surge_cast"], ["steady_gaussian"], ["ideal"], radio="perfect/loss=x")


IGNORE_PEERS = sorted(n for n, a in BUILTIN_ALGORITHMS.items() if ignores_peers(a.behavior))


def test_the_built_ins_that_ignore_their_peers_are_the_single_vehicle_ones() -> None:
    assert (
        sorted(["random_walk", "casting", "surge_cast", "infotaxis", "particle_filter", "oracle"])
        == IGNORE_PEERS
    )


@pytest.mark.parametrize("algorithm", [*IGNORE_PEERS, "gradient_swarm"])
def test_a_behaviour_that_ignores_its_peers_flies_the_same_bits_on_any_radio(
    algorithm: str,
) -> None:
    """Why such a cell is flown once: three of its vehicles fly the same tracks on a link
    that loses half of everything and delays the rest by 1 s; the gradient swarm, which
    reads its peers' readings, does not (so the comparison can fail)."""
    spec = EpisodeSpec(
        algorithm, "meander_low", "ideal", run=0, seed=1000, time_limit_s=40.0,
        keep_trajectory=True, vehicles=3,
    )  # fmt: skip
    perfect, lossy = run_episode(spec), run_episode(replace(spec, overrides=LOSS_05_1S))
    assert len(perfect.trajectories) == len(lossy.trajectories) == 3
    same = (perfect.trajectories, perfect.estimate_xy) == (lossy.trajectories, lossy.estimate_xy)
    assert same == (algorithm != "gradient_swarm")


def test_each_swarm_cell_is_paired_with_the_best_single_vehicle_on_the_same_starts() -> None:
    """The swarm table's paired test against the best 1-vehicle algorithm (most successes,
    the floor and the ceiling left out): on 6 starts, casting alone wins runs 0–3 and
    coop_declare alone runs 0–1, so casting is the best single vehicle; coop_declare ×3
    wins runs 2–5. Counted by hand: ×3 against casting ×1, only ×3 wins runs 4–5 and only
    casting runs 0–1: p = 1 (two against two); casting ×3 (runs 0–5) against casting ×1:
    only ×3 runs 4–5, p = 0.5 (binomial, 2 of 2 at ½)."""
    wins = {
        ("random_walk", 1): set(), ("oracle", 1): {0, 1, 2, 3, 4, 5},
        ("casting", 1): {0, 1, 2, 3}, ("coop_declare", 1): {0, 1},
        ("casting", 3): {0, 1, 2, 3, 4, 5}, ("coop_declare", 3): {2, 3, 4, 5},
    }  # fmt: skip
    opts = make_options(["casting", "coop_declare"], ["meander_low"], ["ideal"], vehicles="1,3")
    outcomes = [
        Outcome(
            EpisodeSpec(a, "meander_low", "ideal", k, 0, vehicles=n), k in won,
            50.0 if k in won else None, 90.0, 50.0, 0.5 if k in won else 9.0, 1.0, True,
            (0.0, 0.0), closest_approach_m=None if n == 1 else 1.0, total_path_m=90.0 * n,
        )
        for (a, n), won in wins.items()
        for k in range(6)
    ]  # fmt: skip
    rows = {(r["algorithm"], r["vehicles"]): r for r in rows_of(opts, outcomes)}
    assert rows["coop_declare", 3]["vs_best_single"] == {
        "algorithm": "casting", "runs": 6, "only_this": 2, "only_single": 2, "p_exact": 1.0,
    }  # fmt: skip
    assert rows["casting", 3]["vs_best_single"] == {
        "algorithm": "casting", "runs": 6, "only_this": 2, "only_single": 0, "p_exact": 0.5,
    }  # fmt: skip
    assert rows["casting", 1]["vs_best_single"]["only_this"] == 0
    labels = {k: r["radio_label"] for k, r in rows.items()}
    assert labels == {k: "perfect" if k == ("coop_declare", 3) else "–" for k in wins}
