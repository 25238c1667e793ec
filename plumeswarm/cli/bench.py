"""``plumeswarm bench``: the benchmarks (scale, envs, gsl and its sweep, pomdp); each command
calls its library function in :mod:`bench` or :mod:`experiments`."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import click

from plumeswarm.cli.common import (
    SCENARIO_OPT,
    SET_OPT,
    Decorator,
    comma_list,
    fail,
    out_dir_option,
    scenario_from,
    vehicles_per_process_option,
)

log = logging.getLogger(__name__)


@click.group()
def bench() -> None:
    """Benchmarks of the full stack."""


def _bench_dir(out: Path | None, bench_name: str) -> Path:
    """``out``, or ``runs/bench-<name>-<local time>/``."""
    import time

    return out or Path("runs") / time.strftime(f"bench-{bench_name}-%Y%m%d-%H%M%S")


def _run_rows(
    run: Callable[[Any, Callable[[str], None]], list[dict[str, object]]],
    opts: object,
    refused: type[Exception],
) -> NoReturn:
    """Run a bench of rows, echoing its progress: ``refused`` (bad options) is one line and exit
    status 2; else exit status 1 when a row holds an error, 0 when none does."""
    try:
        rows = run(opts, click.echo)
    except refused as exc:
        fail(str(exc))
    sys.exit(1 if any("error" in r for r in rows) else 0)


def _int_list(ctx: click.Context, param: click.Parameter, value: str) -> tuple[int, ...]:
    try:
        out = tuple(int(v) for v in value.split(",") if v.strip())
    except ValueError:
        raise click.BadParameter(f"{value!r} is not a comma-separated list of integers") from None
    if not out or min(out) < 1:
        raise click.BadParameter("give at least one count, each >= 1")
    return out


@bench.command("scale")
@SCENARIO_OPT
@click.option(
    "--vehicles",
    default="1,2,4,8,16,32,64",
    callback=_int_list,
    show_default=True,
    help="Comma-separated vehicle counts: one row each (the scenario scaled to each).",
)
@vehicles_per_process_option("Vehicles each autopilot process serves.")
@click.option(
    "--state",
    "states",
    default="grounded,hovering,flying",
    show_default=True,
    help="Comma-separated states the swarm is measured in: grounded, hovering, flying.",
)
@click.option(
    "--seconds",
    type=click.FloatRange(min=0.5),
    default=8.0,
    show_default=True,
    help="Wall seconds each row is measured over, once the swarm is in its state.",
)
@click.option("--no-gateway", is_flag=True, help="Leave the MAVLink gateway out.")
@click.option(
    "--sensor-period-ticks",
    type=click.IntRange(min=1),
    default=None,
    help="Sensor every N control ticks (default: the scenario's).",
)
@click.option(
    "--baseline",
    is_flag=True,
    help="Also measure each row's ceiling: the same processes doing no work but the lockstep.",
)
@click.option(
    "--ros2",
    type=click.Choice(["off", "idle", "subscribed"]),
    default="off",
    show_default=True,
    help="Also run the ROS 2 bridge: with no ROS 2 subscriber (idle) or with one subscribed to "
    "every topic it publishes (subscribed).",
)
@out_dir_option("Directory for scale.json (default: runs/bench-scale-<time>/).")
@SET_OPT
def bench_scale(
    scenario: str | None,
    vehicles: tuple[int, ...],
    vehicles_per_process: int,
    states: str,
    seconds: float,
    no_gateway: bool,
    sensor_period_ticks: int | None,
    baseline: bool,
    ros2: str,
    out: Path | None,
    scenario_overrides: tuple[str, ...],
) -> None:
    """Real-time factor, CPU and memory of the whole stack against the number of vehicles."""
    from plumeswarm.bench.scale import ScaleError, ScaleOptions, run_scale

    opts = ScaleOptions(
        scenario=scenario_from(scenario, scenario_overrides),
        out=_bench_dir(out, "scale"),
        vehicles=vehicles,
        states=comma_list(states),
        seconds=seconds,
        vehicles_per_process=vehicles_per_process,
        gateway=not no_gateway,
        sensor_period_ticks=sensor_period_ticks,
        baseline=baseline,
        ros2=ros2,
    )
    _run_rows(run_scale, opts, ScaleError)


@bench.command("envs")
@SCENARIO_OPT
@click.option(
    "--vehicles",
    default="1,3,16,64",
    callback=_int_list,
    show_default=True,
    help="Comma-separated vehicle counts (the scenario scaled to each).",
)
@click.option(
    "--backends",
    default="fused,bus",
    show_default=True,
    help="Comma-separated: fused (one process, no bus), bus (the distributed stack).",
)
@click.option(
    "--steps", type=click.IntRange(min=1), default=30, show_default=True, help="Timed steps."
)
@click.option(
    "--ticks-per-step", type=click.IntRange(min=1), default=12, show_default=True,
    help="Control ticks per environment step.",
)  # fmt: skip
@vehicles_per_process_option("Bus backend: autopilot processes serve this many vehicles each.")
@out_dir_option("Directory for envs.json (default: runs/bench-envs-<time>/).")
def bench_envs(
    scenario: str | None,
    vehicles: tuple[int, ...],
    backends: str,
    steps: int,
    ticks_per_step: int,
    vehicles_per_process: int,
    out: Path | None,
) -> None:
    """Steps per second and real-time factor of the environments, fused and bus side by side."""
    sc = scenario_from(scenario)
    from plumeswarm.bench.envs import EnvBenchOptions, run_env_bench

    opts = EnvBenchOptions(
        scenario=sc,
        out=_bench_dir(out, "envs"),
        vehicles=vehicles,
        backends=comma_list(backends),
        steps=steps,
        ticks_per_step=ticks_per_step,
        vehicles_per_process=vehicles_per_process,
    )
    _run_rows(run_env_bench, opts, ValueError)


def _gsl_options(seed_default: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """The options ``bench gsl`` and ``bench gsl sweep`` share: one row an option, each shown
    with its default (``--out`` has none)."""
    rows: list[tuple[str, Any, object, str | None]] = [
        ("--algorithms", None, "all", "Comma-separated names, name=module:Class, or 'all'; "
         "random_walk and oracle always run."),
        ("--environments", None, "all", "Comma-separated names (NAME or gsl/NAME, as "
         "`plumeswarm scenario list` shows them), scenario paths, or 'all'."),
        ("--sensors", None, "all", "Comma-separated, or 'all' available."),
        ("--runs", click.IntRange(min=1), 30, "Seeded runs per cell (algorithm × environment "
         "× sensor)."),
        ("--seed", click.IntRange(min=0, max=2**31 - 1), seed_default,
         "Published tables: 0; tuning: >= 1000."),
        ("--time-limit", click.FloatRange(min=1.0), 300.0, "Seconds of simulated time per run."),
        ("--dynamics", click.Choice(["kinematic", "full"]), "kinematic", "kinematic: point "
         "masses following the setpoint; full: pybullet vehicles and autopilots."),
        ("--control-hz", click.IntRange(min=1, max=1000), 20, "Behaviour rate with kinematic "
         "dynamics (full uses the scenario's)."),
        ("--sensor-period-ticks", click.IntRange(min=1), 2, "A reading every N control ticks "
         "(kinematic; full: 10 Hz)."),
        ("--vehicles", None, None, "Vehicles flying each algorithm, e.g. 3 or 1,3,10 (each "
         "count its own cells; default: the algorithm's own; several single-vehicle searchers "
         "fly independently, the first declaration counts)."),
        ("--spacing", click.FloatRange(min=0.0), None, "A swarm's crosswind start spacing, m "
         "(default: the algorithm's; 0: a circle of 2 m)."),
        ("--radio", None, "", "The link between vehicles: loss=P,latency=TICKS,range=M,"
         "bytes=N (default: a perfect link)."),
        ("--jobs", click.IntRange(min=1), 2, "Worker processes."),
    ]  # fmt: skip
    options: list[Decorator] = [
        click.option(
            *([flag, "time_limit_s"] if flag == "--time-limit" else [flag]),
            type=type_,
            default=default,
            show_default=True,
            help=help_text,
        )
        for flag, type_, default, help_text in rows
    ]
    options.append(out_dir_option("Output directory (default runs/bench-gsl-…)."))

    def apply(f: Callable[..., None]) -> Callable[..., None]:
        for option in reversed(options):
            f = option(f)
        return f

    return apply


def _gsl_run(
    kwargs: dict[str, Any],
    run: Callable[[Any, Path, Any], list[Path]],
    check: Callable[[Any], None] | None = None,
) -> None:
    """Validate the options, run with a progress bar, write, and say what was written."""
    import time

    from tqdm import tqdm

    from plumeswarm.gsl.bench import GslError, availability_lines, make_options

    out = kwargs.pop("out")
    jobs = kwargs["jobs"]
    try:
        opts = make_options(
            comma_list(kwargs.pop("algorithms")),
            comma_list(kwargs.pop("environments")),
            comma_list(kwargs.pop("sensors")),
            **kwargs,
        )
        if check is not None:
            check(opts)
    except GslError as exc:
        fail(str(exc))
    for line in availability_lines():
        click.echo(line)
    started = time.monotonic()
    with tqdm(total=1, desc="episodes", unit="run", file=sys.stderr) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        directory = _bench_dir(out, "gsl")
        try:
            written = run(opts, directory, progress)
        except GslError as exc:
            fail(str(exc))
    click.echo(written[0].read_text())
    click.echo(f"wall time {time.monotonic() - started:.0f} s on {jobs} worker process(es)")
    for path in written:
        click.echo(f"wrote {path}")


@bench.group("gsl", invoke_without_command=True)
@_gsl_options(seed_default=0)
@click.pass_context
def bench_gsl(ctx: click.Context, /, **kwargs: Any) -> None:
    """Source seeking: algorithms × environments × sensors, N seeded runs per cell."""
    if ctx.invoked_subcommand is not None:
        return
    from plumeswarm.gsl.bench import rows_of, run_all, write_outputs

    def run(opts: Any, directory: Path, progress: Any) -> list[Path]:
        outcomes = run_all(opts, progress)
        return write_outputs(directory, opts, rows_of(opts, outcomes), outcomes)

    _gsl_run(kwargs, run)


@bench_gsl.command("sweep")
@click.argument("params", nargs=-1, required=True)
@click.option(
    "--allow-test-seeds",
    is_flag=True,
    help="Sweep seeds < 1000 anyway (the output then says so).",
)
@_gsl_options(seed_default=1000)
def bench_gsl_sweep(params: tuple[str, ...], allow_test_seeds: bool, **kwargs: Any) -> None:
    """One table per PARAM=v1,v2,… (behavior.NAME, start.along_m or a scenario section.key)."""
    from plumeswarm.gsl.bench import GslError
    from plumeswarm.gsl.sweep import (
        parse_sweep,
        run_sweep,
        seed_warning,
        value_specs,
        write_sweep,
    )

    try:
        parsed = [parse_sweep(p) for p in params]
    except GslError as exc:
        fail(str(exc))

    def check(opts: Any) -> None:
        warning = seed_warning(opts, allow_test_seeds)
        if warning:
            click.echo(warning, err=True)
        for param in parsed:  # every value valid before any episode flies
            for value in param.values:
                value_specs(opts, param.name, value)

    def run(opts: Any, directory: Path, progress: Any) -> list[Path]:
        tables = run_sweep(opts, parsed, progress)
        return write_sweep(directory, opts, parsed, tables, seed_warning(opts, allow_test_seeds))

    _gsl_run(kwargs, run, check)


@bench.command("pomdp")
@click.option("--dims", type=int, default=2, show_default=True, help="Space dimensions: 1, 2 or 3.")
@click.option("--lambda-over-dx", type=float, default=2.0, show_default=True, help="λ/Δx, >= 1.")
@click.option("--r-dt", type=float, default=2.0, show_default=True, help="R·Δt, > 0.")
@click.option(
    "--episodes", type=int, default=1000, show_default=True, help="Episodes to average over."
)
@click.option(
    "--seed",
    type=int,
    default=0,
    show_default=True,
    help="Seed of the episodes' hits (each episode's own stream derives from it).",
)
@out_dir_option("Directory for pomdp.json (default runs/bench-pomdp-<time>/).")
def bench_pomdp(
    dims: int,
    lambda_over_dx: float,
    r_dt: float,
    episodes: int,
    seed: int,
    out: Path | None,
) -> None:
    """Infotaxis on the source-tracking POMDP (Loisy & Eloy 2022), evaluated as OTTO does."""
    from plumeswarm.bench.pomdp import (
        PomdpError,
        PomdpOptions,
        report_lines,
        run_pomdp,
        write_result,
    )

    try:
        opts = PomdpOptions(dims, lambda_over_dx, r_dt, episodes, seed)
    except PomdpError as exc:
        fail(str(exc))
    step = max(1, episodes // 20)

    def progress(done: int, total: int) -> None:
        if done % step == 0 or done == total:
            click.echo(f"episodes {done}/{total}", err=True)

    result = run_pomdp(opts, progress)
    for line in report_lines(result):
        click.echo(line)
    click.echo(f"wrote {write_result(_bench_dir(out, 'pomdp'), result)}")
