"""The published GSL tables' lines (results/), to compare re-flown episodes with."""

from __future__ import annotations

import csv
from pathlib import Path

from plumeswarm.gsl.bench import make_options, runs_csv, specs_of
from plumeswarm.gsl.episode import run_episode

REPO = Path(__file__).resolve().parents[2]


def published_and_reflown(
    directory: str, algorithm: str, environment: str, runs: int, sensor: str = "ideal"
) -> tuple[list[str], list[str]]:
    """Runs 0 … ``runs`` − 1 of ``algorithm`` in ``environment`` (test seed 0, kinematic): the
    lines ``results/DIRECTORY/runs.csv`` has for them, and the same episodes flown now, as
    ``plumeswarm bench gsl`` writes them."""
    opts = make_options([algorithm], [environment], [sensor], runs=runs, seed=0)
    specs = [s for s in specs_of(opts) if s.algorithm == algorithm]
    new = runs_csv([run_episode(s) for s in specs]).splitlines()[1:]
    lines = (REPO / "results" / directory / "runs.csv").read_text().splitlines()
    wanted = {(algorithm, environment, sensor, str(run)) for run in range(runs)}
    published = [
        line
        for line, row in zip(lines[1:], csv.DictReader(lines), strict=True)
        if (row["algorithm"], row["environment"], row["sensor"], row["run"]) in wanted
        and row["dynamics"] == "kinematic"
    ]
    return published, new
