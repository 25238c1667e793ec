"""``plumeswarm bench survey``: the mass-balance survey flown in the benchmark environments,
its estimated release rate against the true one.

For each environment (a file of ``swarmbus/scenarios/gsl/``, by name, or any scenario path)
and each run k of ``runs``: the environment's scenario with the world seed seed × 100003 + k
(the GSL benchmark's: it seeds the anemometer's noise, the sensor and a time-dependent field's
realisation), the sensor preset, the curtain planned from the scenario's source, mean wind
direction and stability class (:func:`~plumeswarm.survey.pattern.plan_for_scenario`), flown by
the Aerosonde in the fused runner (``dynamics = "plane"``,
:func:`~plumeswarm.survey.plane.fly_plane_survey`) or by the kinematic runner (``"kinematic"``,
:func:`~plumeswarm.survey.flight.fly_survey`: a point on the same kind of racetrack at a
constant ground speed), estimated (:func:`~plumeswarm.survey.flux.estimate_flux`) from all
its sweeps and, with ``repeats`` > 1, from its first 1, 2, … sweeps too. Rows: per
environment, the true rate (the scenario's first source), the estimates' mean and standard
deviation, the mean and RMS error in per cent of the true rate, the largest error, the
curtain's coverage (the share of the time-averaged Gaussian plume's flux that crosses the
flown rectangle, :func:`~plumeswarm.survey.pattern.model_coverage`), the estimate's flown
share, the flight time and, with ``repeats`` > 1, the RMS error of the estimates from the
first 1, 2, … sweeps of the same flights (how the error shrinks with more passes). Prints
the table, writes ``survey.json`` (every run) and ``survey.md`` (the table, the command on its
first line) into the output directory.
"""

from __future__ import annotations

import json
import math
import statistics
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import msgspec

from plumeswarm.gsl.registry import SENSORS, GslError, load_environment, time_dependent
from plumeswarm.survey.flight import (
    SAMPLE_HZ,
    SURVEY_SPEED_M_S,
    SurveyFlight,
    flight_time_s,
    kinematic_flight,
)
from plumeswarm.survey.flux import FluxEstimate, estimate_flux
from plumeswarm.survey.pattern import (
    DEFAULT_DISTANCE_M,
    CurtainPlan,
    SurveyError,
    model_coverage,
    plan_for_scenario,
    scenario_sigmas,
)
from plumeswarm.survey.plane import fly_plane_survey
from swarmbus.scenario import Scenario

ENVIRONMENTS = ("steady_gaussian", "meander_low", "meander_high", "puff_meander")
SEED_STRIDE = 100_003
#: Who flies the survey: the Aerosonde with its autopilot and physics, or a kinematic point.
DYNAMICS = ("plane", "kinematic")


@dataclass(frozen=True)
class SurveyOptions:
    environments: tuple[str, ...] = ENVIRONMENTS
    runs: int = 10
    seed: int = 0
    sensor: str = "ideal"
    distance_m: float = DEFAULT_DISTANCE_M
    speed_m_s: float = 0.0  # 0: the plane's cruise airspeed, the kinematic runner's 18 m/s
    repeats: int = 1
    mean_plume: bool = False  # fly each environment's time-averaged Gaussian, exact wind
    sample_hz: float = SAMPLE_HZ
    dynamics: str = "plane"

    def __post_init__(self) -> None:
        if self.runs < 1:
            raise SurveyError("runs", f"{self.runs!r} must be 1 or more")
        if self.sensor not in SENSORS:
            raise SurveyError("sensor", f"{self.sensor!r} is none of {', '.join(SENSORS)}")
        if not self.environments:
            raise SurveyError("environments", f"none given; shipped: {', '.join(ENVIRONMENTS)}")
        if self.dynamics not in DYNAMICS:
            raise SurveyError("dynamics", f"{self.dynamics!r} is none of {', '.join(DYNAMICS)}")
        if not (math.isfinite(self.speed_m_s) and self.speed_m_s >= 0.0):
            raise SurveyError("speed_m_s", f"{self.speed_m_s!r} must be ≥ 0 (0: the cruise)")


def command_line(opts: SurveyOptions) -> str:
    """The command that makes the table (without --out)."""
    return (
        f"plumeswarm bench survey --environments {','.join(opts.environments)} "
        f"--runs {opts.runs} --seed {opts.seed} --sensor {opts.sensor} "
        f"--dynamics {opts.dynamics} --distance {opts.distance_m:g} --repeats {opts.repeats}"
        + (f" --speed {opts.speed_m_s:g}" if opts.speed_m_s else "")
        + (f" --sample-hz {opts.sample_hz:g}" if opts.sample_hz != SAMPLE_HZ else "")
        + (" --mean-plume" if opts.mean_plume else "")
    )


def mean_plume(scenario: Scenario) -> Scenario:
    """The scenario's time average as the survey would meet it: every source a steady Gaussian
    plume of its atmosphere, in the steady mean wind, read by an anemometer without noise."""
    sources = [msgspec.structs.replace(s, model=None) for s in scenario.plume.sources]
    plume = msgspec.structs.replace(scenario.plume, model="gaussian", sources=sources)
    wind = msgspec.structs.replace(scenario.wind, model="steady")
    anemometer = msgspec.structs.replace(scenario.anemometer, noise_std_m_s=0.0)
    return msgspec.structs.replace(scenario, plume=plume, wind=wind, anemometer=anemometer)


def run_scenario(base: Scenario, opts: SurveyOptions, run: int) -> Scenario:
    """Run ``run``'s scenario: its own seed, the bench's sensor (``mean_plume``: the
    environment's time average, :func:`mean_plume`)."""
    world = msgspec.structs.replace(base.world, seed=opts.seed * SEED_STRIDE + run)
    scenario = msgspec.structs.replace(base, world=world, sensor=SENSORS[opts.sensor].config)
    return mean_plume(scenario) if opts.mean_plume else scenario


@dataclass(frozen=True)
class RunResult:
    """One flight: its estimate and error in per cent of the true rate, or why it has none."""

    run: int
    seed: int
    flight_s: float
    estimate: FluxEstimate | None
    error_pct: float | None
    refused: str | None
    #: The error of the estimate from the first 1, 2, … sweeps (the last: ``error_pct``);
    #: None where the first sweeps gave no estimate.
    sweep_errors_pct: tuple[float | None, ...] = ()


@dataclass(frozen=True)
class Summary:
    """The estimated runs of one environment."""

    mean_g_s: float
    std_g_s: float
    mean_error_pct: float
    rms_error_pct: float
    max_abs_error_pct: float
    flown_fraction: float
    flight_s: float
    #: The RMS error of the estimates from the first 1, 2, … sweeps, over the runs that have one.
    sweep_rms_pct: tuple[float | None, ...] = ()


@dataclass(frozen=True)
class EnvironmentRow:
    environment: str
    scenario_sha256: str
    time_dependent: bool
    true_g_s: float
    heights_m: tuple[float, ...]
    half_width_m: float
    coverage: float
    runs: tuple[RunResult, ...]
    summary: Summary | None

    @property
    def estimated(self) -> int:
        return sum(r.estimate is not None for r in self.runs)


def sensor_lag_s(scenario: Scenario) -> float:
    """The time constant the estimate undoes: the sensor's, when it is a linear first-order lag
    (rise = decay, no metal-oxide transducer); else 0."""
    sensor = scenario.sensor.resolved()
    if sensor.mox is not None or sensor.rise_time_constant_s != sensor.decay_time_constant_s:
        return 0.0
    return sensor.rise_time_constant_s or 0.0


def fly(scenario: Scenario, plan: CurtainPlan, opts: SurveyOptions) -> SurveyFlight:
    """The survey flown by ``opts.dynamics``."""
    if opts.dynamics == "kinematic":
        speed = opts.speed_m_s or SURVEY_SPEED_M_S
        return kinematic_flight(scenario, plan, speed, opts.repeats, opts.sample_hz)
    return fly_plane_survey(scenario, plan, opts.repeats, opts.sample_hz, opts.speed_m_s)


def survey_run(base: Scenario, opts: SurveyOptions, run: int) -> RunResult:
    """One flight and its estimate (or the reason there is none), and the errors of the
    estimates from its first sweeps."""
    scenario = run_scenario(base, opts, run)
    plan = plan_for_scenario(scenario, opts.distance_m)
    flight = fly(scenario, plan, opts)
    true_q = scenario.plume.sources[0].release_rate_g_s
    lag, tolerance = sensor_lag_s(scenario), flight.height_tolerance_m
    seed, flight_s = scenario.world.seed, flight_time_s(flight.readings)
    errors: list[float | None] = []
    for sweeps in range(1, opts.repeats):
        try:
            part = estimate_flux(
                flight.through_sweep(sweeps), plan, height_tolerance_m=tolerance, sensor_lag_s=lag
            )
        except SurveyError:
            errors.append(None)
            continue
        errors.append(100.0 * (part.release_rate_g_s - true_q) / true_q)
    try:
        estimate = estimate_flux(
            flight.readings, plan, height_tolerance_m=tolerance, sensor_lag_s=lag
        )
    except SurveyError as exc:
        return RunResult(run, seed, flight_s, None, None, str(exc), (*errors, None))
    error = 100.0 * (estimate.release_rate_g_s - true_q) / true_q
    return RunResult(run, seed, flight_s, estimate, error, None, (*errors, error))


def _rms(values: list[float]) -> float | None:
    return math.sqrt(statistics.fmean(v * v for v in values)) if values else None


def summary_of(runs: tuple[RunResult, ...]) -> Summary | None:
    good = [(r, r.estimate) for r in runs if r.estimate is not None and r.error_pct is not None]
    if not good:
        return None
    q = [e.release_rate_g_s for _, e in good]
    err = [r.error_pct for r, _ in good if r.error_pct is not None]
    return Summary(
        mean_g_s=statistics.fmean(q),
        std_g_s=statistics.stdev(q) if len(q) > 1 else 0.0,
        mean_error_pct=statistics.fmean(err),
        rms_error_pct=math.sqrt(statistics.fmean(e * e for e in err)),
        max_abs_error_pct=max(abs(e) for e in err),
        flown_fraction=statistics.fmean(e.flown_fraction for _, e in good),
        flight_s=statistics.fmean(r.flight_s for r, _ in good),
        sweep_rms_pct=tuple(
            _rms([e for e in sweep if e is not None])
            for sweep in zip(*(r.sweep_errors_pct for r in runs), strict=True)
        ),
    )


def environment_row(name: str, opts: SurveyOptions) -> EnvironmentRow:
    """Every run in environment ``name`` and their summary."""
    try:
        env = load_environment(name)
    except GslError as exc:
        raise SurveyError("environments", str(exc)) from None
    scenario = env.scenario
    plan = plan_for_scenario(scenario, opts.distance_m)
    sigma_y, sigma_z = scenario_sigmas(scenario, opts.distance_m)
    source = scenario.plume.sources[0]
    runs = tuple(survey_run(scenario, opts, k) for k in range(opts.runs))
    return EnvironmentRow(
        environment=env.name,
        scenario_sha256=env.sha256,
        time_dependent=time_dependent(scenario) and not opts.mean_plume,
        true_g_s=source.release_rate_g_s,
        heights_m=plan.heights_m,
        half_width_m=plan.half_width_m,
        coverage=model_coverage(plan, sigma_y, sigma_z, source.release_height_m),
        runs=runs,
        summary=summary_of(runs),
    )


HEADER = (
    "| environment | runs estimated | true Q (g/s) | estimated Q (g/s), mean ± std | "
    "mean error | RMS error | largest error | coverage | flown share | flight |"
)


def _sweeps_cell(s: Summary) -> str:
    return " / ".join("–" if e is None else f"{e:.1f}" for e in s.sweep_rms_pct) + " %"


def table_lines(opts: SurveyOptions, rows: list[EnvironmentRow]) -> list[str]:
    """The markdown table, the command above it; with ``repeats`` > 1 a column of the RMS
    error from the first 1, 2, … sweeps."""
    sweeps = opts.repeats > 1
    header = HEADER + (
        f" RMS error after {' / '.join(str(k + 1) for k in range(opts.repeats))} sweeps |"
        if sweeps
        else ""
    )
    columns = 10 + sweeps
    lines = [f"`{command_line(opts)}`", "", header, "|---" * columns + "|"]
    for r in rows:
        head = f"| `{r.environment}` | {r.estimated}/{len(r.runs)} | {r.true_g_s:g} |"
        s = r.summary
        if s is None:
            lines.append(head + " – |" * (columns - 3))
            continue
        lines.append(
            f"{head} {s.mean_g_s:.2f} ± {s.std_g_s:.2f} | {s.mean_error_pct:+.1f} % | "
            f"{s.rms_error_pct:.1f} % | {s.max_abs_error_pct:.1f} % | "
            f"{100.0 * r.coverage:.1f} % | {100.0 * s.flown_fraction:.1f} % | "
            f"{s.flight_s:.0f} s |" + (f" {_sweeps_cell(s)} |" if sweeps else "")
        )
    return lines


def run_survey_bench(
    opts: SurveyOptions, out: Path, echo: Callable[[str], None]
) -> list[EnvironmentRow]:
    """Fly every environment's runs, print the table, write ``survey.json`` and ``survey.md``."""
    rows = []
    for name in opts.environments:
        rows.append(environment_row(name, opts))
        for r in rows[-1].runs:
            if r.refused is not None:
                echo(f"{name} run {r.run}: {r.refused}")
    lines = table_lines(opts, rows)
    for line in lines:
        echo(line)
    out.mkdir(parents=True, exist_ok=True)
    (out / "survey.md").write_text("\n".join(lines) + "\n")
    document = {
        "command": command_line(opts),
        "options": asdict(opts),
        "rows": [asdict(r) for r in rows],
    }
    (out / "survey.json").write_text(json.dumps(document, indent=1) + "\n")
    echo(f"wrote {out / 'survey.md'} and {out / 'survey.json'}")
    return rows
