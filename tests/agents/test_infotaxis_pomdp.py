"""Infotaxis on its own model, against a second implementation: Loisy & Eloy's OTTO.

``plumeswarm bench pomdp`` runs our infotaxis core (agents/behaviors/infotaxis_core.py) on the
source-tracking POMDP as OTTO defines and evaluates it. OTTO's number below comes from OTTO
itself, run on its own code (docs/gsl.md "Infotaxis on its own model" has the command):

    OTTO 1.0.2, github.com/C0PEP0D/otto at commit 1467029f399dc5eeac8652499a9c8326ecab4575,
    otto/evaluate/evaluate.py with N_DIMS = 2, LAMBDA_OVER_DX = 2.0, R_DT = 2.0, POLICY = 0
    (infotaxis), STEPS_AHEAD = 1, every other parameter its default (adaptive number of
    episodes to a 1 % relative standard error, STOP_p = 1e-6, grid and hit cap automatic).

The comparison is a two-sample test of the means at the 5 % level: OTTO prints its mean
with ±1.96 standard errors (of the per-episode expected arrival times), ours reports the same
interval; the two agree when the difference of the means is within 1.96 × √(SE_OTTO² +
SE_ours²), i.e. the 95 % interval of the difference contains 0. Testing only "OTTO's mean
within our interval" would ignore OTTO's own error; "the intervals overlap" would accept
differences of up to twice that, a test at about the 0.5 % level.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from tests.support.procs import run_cli

#: OTTO's evaluation of infotaxis, 2D, λ/Δx = 2, R·Δt = 2 (see the module docstring).
#: It printed "mean number of steps to find the source: 24.351 +/- 0.458" after 8124 episodes
#: (N_GRID = 37, N_HITS = 4, STOP_t = 1283; probability never found 1.4991e-05; 1 failed
#: episode, stuck; standard deviation of T 23.998).
OTTO_EPISODES = 8124
OTTO_MEAN_STEPS = 24.351
OTTO_HALF_CI95 = 0.458
OTTO_GRID, OTTO_HITS, OTTO_STEP_LIMIT = 37, 4, 1283
OTTO_P_NOT_FOUND = 1.4991e-05

EPISODES = 3000


@pytest.mark.timeout(900)  # 36 s of CPU; 5 min of wall time at load average 12
def test_infotaxis_on_the_2d_pomdp_takes_otto_s_mean_number_of_steps(tmp_path: Path) -> None:
    res = run_cli(
        [
            "bench", "pomdp", "--dims", "2", "--lambda-over-dx", "2", "--r-dt", "2",
            "--episodes", str(EPISODES), "--seed", "0", "--out", str(tmp_path),
        ],
        timeout_s=900.0,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    got = json.loads((tmp_path / "pomdp.json").read_text())
    assert (got["grid"], got["n_hits"], got["step_limit"]) == (
        OTTO_GRID,
        OTTO_HITS,
        OTTO_STEP_LIMIT,
    )
    assert got["episodes"] == EPISODES
    mean = got["mean_arrival_steps"]
    low, high = got["mean_arrival_ci95"]
    assert low < mean < high
    se_ours = (high - low) / 2 / 1.96
    se_otto = OTTO_HALF_CI95 / 1.96
    difference = mean - OTTO_MEAN_STEPS
    assert abs(difference) <= 1.96 * math.hypot(se_ours, se_otto), (
        f"ours {mean:.2f} ({low:.2f}–{high:.2f}), OTTO {OTTO_MEAN_STEPS:.2f} ± {OTTO_HALF_CI95:.2f}"
    )
    # both almost always find the source
    assert got["p_failure"] < 1e-3 and OTTO_P_NOT_FOUND < 1e-3


def test_bench_pomdp_says_what_is_wrong_with_a_bad_option(tmp_path: Path) -> None:
    for args, message in (
        (["--dims", "4"], "--dims must be 1, 2 or 3, got 4"),
        (["--lambda-over-dx", "0.5"], "--lambda-over-dx must be >= 1, got 0.5"),
        (["--r-dt", "0"], "--r-dt must be > 0, got 0.0"),
        (["--episodes", "0"], "--episodes must be >= 1, got 0"),
    ):
        res = run_cli(["bench", "pomdp", *args, "--out", str(tmp_path)])
        assert res.returncode == 2
        assert res.stderr.strip().splitlines() == [f"plumeswarm: error: {message}"], res.stderr
    assert not (tmp_path / "pomdp.json").exists()
