"""``plumeswarm chaos SCENARIO --seconds S --seed N``: processes killed at random (seeded)
moments of a stepped run, every vehicle's state stream compared with a fault-free run
(:mod:`plumeswarm.experiments.chaos`, docs/reliability.md "Chaos")."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from plumeswarm.cli.common import fail, scenario_from


@click.command()
@click.argument("scenario", required=False, default=None, metavar="[FILE|NAME]")
@click.option(
    "--seconds", type=float, default=20.0, show_default=True, help="Sim seconds of each run."
)
@click.option("--seed", type=int, default=1, show_default=True, help="Draws the faults.")
@click.option(
    "--faults", type=int, default=20, show_default=True, help="Processes killed in the run."
)
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Run directory (default runs/chaos-<timestamp>/).",
)
def chaos(scenario: str | None, seconds: float, seed: int, faults: int, out: Path | None) -> None:
    """Kill processes at seeded moments of a run; compare the vehicles with a fault-free run."""
    import time

    from deploy.scaling import ScalingError, multirotors_only
    from plumeswarm.experiments.chaos import ChaosOptions, run_chaos
    from swarmbus.scenario import resolve_scenario_path

    if seconds <= 0.0:
        fail(f"--seconds must be > 0, got {seconds:g}")
    if faults < 1:
        fail(f"--faults must be >= 1, got {faults}")
    sc = scenario_from(scenario)
    try:
        multirotors_only(sc, "a restarted plane's autopilot does not resume bit for bit")
    except ScalingError as exc:
        fail(str(exc))
    path = resolve_scenario_path(scenario)
    run_dir = out or Path("runs") / f"chaos-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"--out {run_dir}: {exc.strerror or exc}")
    opts = ChaosOptions(sc, path, run_dir, seconds, seed, faults)
    sys.exit(run_chaos(opts, click.echo))
