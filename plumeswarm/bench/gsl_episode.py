"""What one kinematic GSL benchmark episode costs: CPU and wall seconds per episode of each
algorithm, flown in this process as ``plumeswarm bench gsl`` flies it.

Run with ``python -m plumeswarm.bench.gsl_episode [--algorithms infotaxis,particle_filter]
[--environments meander_low] [--sensor ideal] [--runs 3] [--seed 1000] [--out FILE.json]``.
Each algorithm first flies a 5 s episode (imports, first calls), then runs 0 … ``--runs`` − 1
of ``plumeswarm.gsl.episode.run_episode(EpisodeSpec(ALGORITHM, ENVIRONMENT, SENSOR, RUN,
SEED))`` — the whole episode: the time-dependent field's warm-up, the flight to a declaration
or the time limit. CPU seconds are this process's (``time.process_time``), less sensitive to a
shared machine than the wall seconds beside them; the table says the load average it was
measured at. Prints a table and writes JSON (default ``runs/bench-gsl-episode.json``); the
default seed 1000 is a tuning seed, not the published tables' test seed 0.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path
from typing import Any

from plumeswarm.gsl.episode import EpisodeSpec, run_episode

REPO = Path(__file__).resolve().parent.parent.parent
WARMUP_LIMIT_S = 5.0


def measure(algorithm: str, environment: str, sensor: str, runs: int, seed: int) -> dict[str, Any]:
    """Every run's CPU and wall seconds, sim seconds flown and outcome."""
    run_episode(EpisodeSpec(algorithm, environment, sensor, 0, seed, WARMUP_LIMIT_S))
    episodes = []
    for run in range(runs):
        spec = EpisodeSpec(algorithm, environment, sensor, run, seed)
        cpu, wall = time.process_time(), time.perf_counter()
        outcome = run_episode(spec)
        cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
        episodes.append(
            {
                "run": run,
                "cpu_s": cpu,
                "wall_s": wall,
                "declared": outcome.declared,
                "final_error_m": outcome.final_error_m,
            }
        )
    cpu_s = [e["cpu_s"] for e in episodes]
    return {
        "algorithm": algorithm,
        "environment": environment,
        "sensor": sensor,
        "seed": seed,
        "episodes": episodes,
        "cpu_s_mean": sum(cpu_s) / len(cpu_s),
        "cpu_s_max": max(cpu_s),
        "load1": os.getloadavg()[0],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--algorithms", default="infotaxis,particle_filter")
    parser.add_argument("--environments", default="meander_low")
    parser.add_argument("--sensor", default="ideal")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--seed", type=int, default=1000)
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "bench-gsl-episode.json")
    args = parser.parse_args()
    if args.runs < 1:
        parser.error(f"--runs {args.runs}: at least 1")
    rows = [
        measure(a, e, args.sensor, args.runs, args.seed)
        for e in args.environments.split(",")
        for a in args.algorithms.split(",")
    ]
    print(time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()))
    print(
        f"{'algorithm':18}{'environment':16}{'CPU s per episode (mean, max)':>32}"
        f"{'wall s (mean)':>15}{'load1':>7}"
    )
    for r in rows:
        wall = sum(e["wall_s"] for e in r["episodes"]) / len(r["episodes"])
        spread = f"{r['cpu_s_mean']:.2f}, {r['cpu_s_max']:.2f}"
        print(f"{r['algorithm']:18}{r['environment']:16}{spread:>32}{wall:15.2f}{r['load1']:7.1f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
