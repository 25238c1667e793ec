"""``plumeswarm chaos SCENARIO --seconds S --seed N``: processes killed at random (seeded)
moments of a stepped run, several at once and during the hold for an earlier kill's restart,
every vehicle's state stream compared with a fault-free run
(:mod:`plumeswarm.experiments.chaos`, docs/reliability.md "Chaos")."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from plumeswarm.cli.common import fail, scenario_from, vehicles_per_process_option


@click.command()
@click.argument("scenario", required=False, default=None, metavar="[FILE|NAME]")
@click.option(
    "--seconds", type=float, default=20.0, show_default=True, help="Sim seconds of each run."
)
@click.option("--seed", type=int, default=1, show_default=True, help="Draws the faults.")
@click.option(
    "--faults",
    type=int,
    default=20,
    show_default=True,
    help="Processes killed in the run, in all (each may be restarted 3 times).",
)
@click.option(
    "--concurrent",
    type=int,
    default=3,
    show_default=True,
    help="At most this many distinct processes killed at the same moment (1: one at a time).",
)
@click.option(
    "--in-hold",
    type=float,
    default=0.3,
    show_default=True,
    help="Share of the kills followed by another while the clock is held for their restarts "
    "(0: always wait until they are back).",
)
@click.option(
    "--vehicles",
    type=click.IntRange(1, 1024),
    default=None,
    help="Scale the scenario to N vehicles (default: its own).",
)
@vehicles_per_process_option("Vehicles each autopilot process serves.")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Run directory (default runs/chaos-<timestamp>/).",
)
def chaos(
    scenario: str | None,
    seconds: float,
    seed: int,
    faults: int,
    concurrent: int,
    in_hold: float,
    vehicles: int | None,
    vehicles_per_process: int,
    out: Path | None,
) -> None:
    """Kill processes at seeded moments of a run, several at once and during the hold for an
    earlier kill's restart; compare the vehicles with a fault-free run."""
    import time

    from deploy.scaling import ScalingError, multirotors_only, scale_scenario
    from plumeswarm.experiments.chaos import ChaosOptions, restart_budget, run_chaos
    from swarmbus.scenario import resolve_scenario_path

    if seconds <= 0.0:
        fail(f"--seconds must be > 0, got {seconds:g}")
    if faults < 1:
        fail(f"--faults must be >= 1, got {faults}")
    if concurrent < 1:
        fail(f"--concurrent must be >= 1, got {concurrent}")
    if not 0.0 <= in_hold <= 1.0:
        fail(f"--in-hold must be in 0..1, got {in_hold:g}")
    sc = scenario_from(scenario)
    try:
        multirotors_only(sc, "a restarted plane's autopilot does not resume bit for bit")
        if vehicles is not None:
            sc = scale_scenario(sc, vehicles)
    except ScalingError as exc:
        fail(str(exc))
    processes, budget = restart_budget(sc, vehicles_per_process)
    if faults > budget:
        fail(
            f"--faults {faults}: the run's {processes} processes may be restarted {budget} "
            f"times in all; valid: 1..{budget}"
        )
    path = resolve_scenario_path(scenario)
    run_dir = out or Path("runs") / f"chaos-{time.strftime('%Y%m%d-%H%M%S')}"
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        fail(f"--out {run_dir}: {exc.strerror or exc}")
    opts = ChaosOptions(
        sc,
        path,
        run_dir,
        seconds,
        seed,
        faults,
        concurrent=concurrent,
        in_hold=in_hold,
        vehicles_per_process=vehicles_per_process,
    )
    sys.exit(run_chaos(opts, click.echo))
