"""``plumeswarm bench``: the benchmarks (scale, envs, gsl and its sweep, pomdp); each command
calls its library function in :mod:`bench` or :mod:`experiments`."""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass
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
    help="Comma-separated: fused (one process, no bus), bus (the distributed stack), pyflyt "
    "(PyFlyt's Aviary, in a virtualenv of its own), floor (the same pybullet bodies alone).",
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


def _gsl_options(
    seed_default: int, environments_help: str = "'all'"
) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """The options ``bench gsl`` and ``bench gsl sweep`` share: one row an option, each shown
    with its default (``--out`` and ``--shard`` have none)."""
    rows: list[tuple[str, Any, object, str | None]] = [
        ("--algorithms", None, "all", "Comma-separated names, name=module:Class, or 'all'; "
         "random_walk and oracle always run."),
        ("--environments", None, "all", "Comma-separated names (NAME or gsl/NAME, as "
         f"`plumeswarm scenario list` shows them), scenario paths, or {environments_help}."),
        ("--sensors", None, "all", "Comma-separated, or 'all' available."),
        ("--runs", click.IntRange(min=1), 30, "Seeded runs per cell (algorithm × environment "
         "× sensor)."),
        ("--seed", click.IntRange(min=0, max=2**31 - 1), seed_default,
         "Published tables: 0; tuning: >= 1000."),
        ("--time-limit", None, "300", "Seconds of simulated time per run in a fixed "
         "environment, or auto: 10 × the straight flight from the start at 2 m/s (a "
         "randomised family always uses its own multiple)."),
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
         "bytes=N, or perfect (the default); several separated by / (e.g. "
         "perfect/loss=0.5,latency=20), each its own cells."),
        ("--jobs", click.IntRange(min=1), 2, "Worker processes (--executor local)."),
        ("--executor", None, "local", "local: a pool of --jobs processes; ray: a Ray started "
         "for the run; ray=ADDRESS: a Ray cluster (ray=auto: the one on this machine). Needs "
         "plumeswarm[cluster]."),
        ("--shard", None, None, "i/N: run only every N-th episode from the i-th; put the N "
         "directories together with 'bench gsl merge'."),
    ]  # fmt: skip
    options: list[Decorator] = [
        click.option(
            *([flag, "time_limit_s"] if flag == "--time-limit" else [flag]),
            type=type_,
            default=default,
            show_default=default is not None,
            help=help_text,
        )
        for flag, type_, default, help_text in rows
    ]
    options.append(
        out_dir_option(
            "Output directory (default runs/bench-gsl-…). Run again with the same options and "
            "--out to resume: only the episodes it lacks run."
        )
    )

    def apply(f: Callable[..., None]) -> Callable[..., None]:
        for option in reversed(options):
            f = option(f)
        return f

    return apply


#: The options that make the grid (the others say where and how it runs).
GRID_ARGS = (
    "algorithms",
    "environments",
    "sensors",
    "runs",
    "seed",
    "time_limit_s",
    "dynamics",
    "control_hz",
    "sensor_period_ticks",
    "vehicles",
    "radio",
    "spacing",
)


@dataclass
class _Grid:
    """A grid built from its options: its episodes, its command, how its tables are written."""

    specs: list[Any]
    command: str
    finish: Callable[[Path, list[Any]], list[Path]]
    warning: str | None = None


def _grid(kind: str, args: dict[str, Any], jobs: int = 1) -> _Grid:
    """``bench gsl`` (kind ``gsl``) or its ``sweep`` from the options in ``args``;
    :class:`GslError` names a bad one."""
    from plumeswarm.gsl.bench import command_line, make_options, rows_of, specs_of, write_outputs
    from plumeswarm.gsl.registry import tuning_environment_names
    from plumeswarm.gsl.sweep import (
        parse_sweep,
        sweep_command,
        sweep_groups,
        sweep_tables,
        tuning_warning,
        write_sweep,
    )

    params = [parse_sweep(p) for p in args.get("params", ())]
    environments = comma_list(args["environments"])
    if kind == "sweep" and list(environments) in ([], ["all"]):
        environments = tuple(tuning_environment_names())
    opts = make_options(
        comma_list(args["algorithms"]),
        environments,
        comma_list(args["sensors"]),
        jobs=jobs,
        **{k: args[k] for k in GRID_ARGS[3:]},
    )
    if kind == "gsl":

        def finish(directory: Path, outcomes: list[Any]) -> list[Path]:
            return write_outputs(directory, opts, rows_of(opts, outcomes), outcomes)

        return _Grid(specs_of(opts), command_line(opts), finish)
    warning = tuning_warning(
        opts, args["allow_test_seeds"], args.get("allow_test_environments", False)
    )
    groups = sweep_groups(opts, params)  # every value valid before any episode flies

    def finish_sweep(directory: Path, outcomes: list[Any]) -> list[Path]:
        return write_sweep(directory, opts, params, sweep_tables(groups, outcomes), warning)

    specs = [s for _, _, specs in groups for s in specs]
    return _Grid(specs, sweep_command(opts, params), finish_sweep, warning)


def _gsl_run(kind: str, kwargs: dict[str, Any]) -> None:
    """Validate the options, open (or resume) the output directory, run with a progress bar,
    write, and say what was written."""
    import time

    from tqdm import tqdm

    from plumeswarm.gsl.bench import GslError, availability_lines, run_specs, throughput_lines
    from plumeswarm.gsl.grid import (
        Journal,
        check_executor,
        grid_header,
        parse_executor,
        parse_shard,
    )

    args = {k: v for k, v in kwargs.items() if k not in ("out", "jobs", "executor", "shard")}
    # seconds as a number, as the journal has always kept them (auto, or a bad value
    # make_options names, stays a word)
    with contextlib.suppress(ValueError):
        args["time_limit_s"] = float(args["time_limit_s"])
    directory = _bench_dir(kwargs["out"], "gsl")
    try:
        executor = parse_executor(kwargs["executor"])
        shard = None if kwargs["shard"] is None else parse_shard(kwargs["shard"])
        check_executor(executor)
        grid = _grid(kind, args, kwargs["jobs"])
        journal = Journal.open(directory, grid_header(kind, args, grid.command, grid.specs, shard))
    except GslError as exc:
        fail(str(exc))
    if grid.warning:
        click.echo(grid.warning, err=True)
    for line in availability_lines():
        click.echo(line)
    started = time.monotonic()
    cpu_s: dict[Any, float] = {}
    with tqdm(total=1, desc="episodes", unit="run", file=sys.stderr) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        try:
            outcomes = run_specs(
                grid.specs,
                kwargs["jobs"],
                progress,
                executor=executor,
                journal=journal,
                shard=shard,
                log=click.echo,
                cpu_s=cpu_s,
                warn=lambda line: tqdm.write(line, file=sys.stderr),
            )
        except GslError as exc:
            fail(str(exc))
    for line in throughput_lines(cpu_s) if cpu_s else []:
        click.echo(line)
    workers = f"{kwargs['jobs']} worker process(es)" if executor.kind == "local" else executor
    click.echo(f"wall time {time.monotonic() - started:.0f} s on {workers}")
    if shard is not None:
        click.echo(
            f"shard {shard}: {len(outcomes)} episodes in {journal.path}; when all "
            f"{shard.count} have run: plumeswarm bench gsl merge DIR... --out DIR"
        )
        return
    _finish(grid, directory, outcomes)


def _finish(grid: _Grid, directory: Path, outcomes: list[Any]) -> None:
    written = grid.finish(directory, outcomes)
    click.echo(written[0].read_text())
    for path in written:
        click.echo(f"wrote {path}")


@bench.group("gsl", invoke_without_command=True)
@_gsl_options(seed_default=0)
@click.pass_context
def bench_gsl(ctx: click.Context, /, **kwargs: Any) -> None:
    """Source seeking: algorithms × environments × sensors, N seeded runs per cell."""
    if ctx.invoked_subcommand is None:
        _gsl_run("gsl", kwargs)


@bench_gsl.command("sweep")
@click.argument("params", nargs=-1, required=True)
@click.option(
    "--allow-test-seeds",
    is_flag=True,
    help="Sweep seeds < 1000 anyway (the output then says so).",
)
@click.option(
    "--allow-test-environments",
    is_flag=True,
    help="Sweep the published tables' environments anyway (the output then says so).",
)
@_gsl_options(seed_default=1000, environments_help="'all': every tuning environment")
def bench_gsl_sweep(
    params: tuple[str, ...], allow_test_seeds: bool, allow_test_environments: bool, **kwargs: Any
) -> None:
    """One table per PARAM=v1,v2,… (behavior.NAME, start.along_m or a scenario section.key),
    on the tuning seeds and environments."""
    _gsl_run(
        "sweep",
        {
            **kwargs,
            "params": list(params),
            "allow_test_seeds": allow_test_seeds,
            "allow_test_environments": allow_test_environments,
        },
    )


@bench_gsl.command("merge")
@click.argument("dirs", nargs=-1, required=True, type=click.Path(file_okay=False, path_type=Path))
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Where the whole grid's tables go.",
)
def bench_gsl_merge(dirs: tuple[Path, ...], out: Path) -> None:
    """Put the --out directories of a grid's shards (bench gsl or sweep --shard i/N) together:
    the same tables as the grid run at once."""
    from plumeswarm.gsl.bench import GslError
    from plumeswarm.gsl.grid import (
        Journal,
        grid_digest,
        merge_journals,
        missing_episodes,
        outcome_of,
        spec_key,
    )

    try:
        merged = merge_journals(dirs)
        header = merged.header
        grid = _grid(header["kind"], header["args"])
        if grid_digest(grid.specs) != header["digest"]:
            raise GslError(
                f"merge: `{header['command']}` makes other episodes in this build than in the "
                "one that ran the shards"
            )
        missing_episodes(merged, grid.specs)
        journal = Journal.open(out, header)
    except GslError as exc:
        fail(str(exc))
    outcomes = [outcome_of(s, merged.records[spec_key(s)]) for s in grid.specs]
    for outcome in {o.spec: o for o in outcomes}.values():
        if spec_key(outcome.spec) not in journal.records:
            journal.append(outcome, merged.behaviors.get(spec_key(outcome.spec)))
    click.echo(f"merged {len(merged.records)} episodes from {len(dirs)} directories")
    _finish(grid, out, outcomes)


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


#: ``bench survey``'s options, one row each: name, type, default, help.
_SURVEY_OPTIONS: list[tuple[str, Any, object, str]] = [
    ("--environments", str, "steady_gaussian,meander_low,meander_high,puff_meander",
     "Comma-separated environment names (NAME or gsl/NAME) or scenario paths."),
    ("--runs", click.IntRange(min=1), 10, "Runs each."),
    ("--seed", int, 0, "Run k flies world seed seed·100003 + k."),
    ("--sensor", click.Choice(["ideal", "mox", "pid"]), "ideal",
     "The sensor preset the vehicle reads through."),
    ("--distance", float, 50.0, "The curtain's distance downwind of the source (m)."),
    ("--dynamics", click.Choice(["plane", "kinematic"]), "plane",
     "Who flies it: the Aerosonde (autopilot and physics) or a kinematic point."),
    ("--speed", float, 0.0,
     "The plane's airspeed or the point's ground speed (m/s); 0: the plane's cruise, 18 m/s."),
    ("--repeats", click.IntRange(min=1), 1, "Sweeps of the curtain (up, down, up, …)."),
    ("--sample-hz", float, 20.0, "Readings per second of sim time."),
]  # fmt: skip
_MEAN_PLUME_HELP = (
    "Fly each environment's time average instead (its steady Gaussian plume, the mean wind, an "
    "anemometer without noise): the method's own bias."
)


def _survey_options(f: Callable[..., None]) -> Callable[..., None]:
    for name, kind, default, text in reversed(_SURVEY_OPTIONS):
        f = click.option(name, type=kind, default=default, show_default=True, help=text)(f)
    return f


@bench.command("survey")
@_survey_options
@click.option("--mean-plume", is_flag=True, help=_MEAN_PLUME_HELP)
@out_dir_option("Directory for survey.md and survey.json (default runs/bench-survey-<time>/).")
def bench_survey(
    environments: str,
    runs: int,
    seed: int,
    sensor: str,
    dynamics: str,
    distance: float,
    speed: float,
    repeats: int,
    sample_hz: float,
    mean_plume: bool,
    out: Path | None,
) -> None:
    """Mass-balance survey: a curtain of crosswind legs downwind of the source, the release
    rate estimated from the readings against the true one (docs/survey.md)."""
    from plumeswarm.survey.bench import SurveyOptions, run_survey_bench
    from plumeswarm.survey.pattern import SurveyError

    try:
        opts = SurveyOptions(
            comma_list(environments),
            runs,
            seed,
            sensor,
            distance,
            speed,
            repeats,
            mean_plume,
            sample_hz,
            dynamics,
        )
        rows = run_survey_bench(opts, _bench_dir(out, "survey"), click.echo)
    except SurveyError as exc:
        fail(str(exc))
    sys.exit(1 if any(r.summary is None for r in rows) else 0)
