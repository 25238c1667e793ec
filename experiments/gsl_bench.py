"""``plumeswarm bench gsl``: source-seeking algorithms × environments × sensors, N seeded runs.

Every cell runs the same N starts (:func:`experiments.gsl_episode.start_point`), spread over the
worker processes; the episodes are independent and seeded from (seed, run, vehicle), so the
table and ``gsl.json`` are the same bytes for the same arguments whatever the number of
workers. Columns (docs/gsl.md): success % with its Wilson 95 % interval, median
time to success with its interquartile range, median path length, median path / initial
distance, median final error, mean detections per minute.
"""

from __future__ import annotations

import functools
import json
import math
import multiprocessing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from experiments.gsl_episode import (
    ALGORITHMS,
    ENVIRONMENTS,
    SENSORS,
    EpisodeSpec,
    Outcome,
    run_episode,
)
from swarmbus.scenario import Scenario, load_scenario

DYNAMICS = ("kinematic", "full")
Z_95 = 1.959963984540054


class GslError(ValueError):
    """A bad option: one line naming it and the bad value."""


@dataclass(frozen=True)
class GslOptions:
    algorithms: tuple[str, ...]
    environments: tuple[str, ...]
    sensors: tuple[str, ...]
    runs: int = 30
    seed: int = 0
    time_limit_s: float = 300.0
    control_hz: int = 20
    sensor_period_ticks: int = 2
    dynamics: str = "kinematic"
    jobs: int = 2


def _pick(kind: str, asked: Sequence[str], registry: dict[str, Any]) -> tuple[str, ...]:
    if not asked or list(asked) == ["all"]:
        return tuple(k for k, v in registry.items() if getattr(v, "missing", None) is None)
    for name in asked:
        if name not in registry:
            raise GslError(f"--{kind} {name!r}: unknown; valid: {', '.join(registry)}")
        missing = getattr(registry[name], "missing", None)
        if missing is not None:
            raise GslError(f"--{kind} {name!r}: unavailable in this build (needs {missing})")
    return tuple(asked)


def make_options(
    algorithms: Sequence[str],
    environments: Sequence[str],
    sensors: Sequence[str],
    **kwargs: Any,
) -> GslOptions:
    """Validated options; :class:`GslError` names the bad option."""
    dynamics = kwargs.get("dynamics", "kinematic")
    if dynamics not in DYNAMICS:
        raise GslError(f"--dynamics {dynamics!r}: valid: {', '.join(DYNAMICS)}")
    if dynamics == "full":  # the real controller runs at the scenario's rates
        base = _base_scenario()
        kwargs["control_hz"] = base.time.control_hz
        kwargs["sensor_period_ticks"] = base.sensor.period_ticks
    return GslOptions(
        algorithms=_pick("algorithms", algorithms, ALGORITHMS),
        environments=_pick("environments", environments, ENVIRONMENTS),
        sensors=_pick("sensors", sensors, SENSORS),
        **kwargs,
    )


def availability_lines() -> list[str]:
    """Which environments and sensors this build can simulate, and what the others need."""
    lines = []
    for kind, registry in (("environments", ENVIRONMENTS), ("sensors", SENSORS)):
        have = [k for k, v in registry.items() if v.missing is None]
        lines.append(f"{kind} available: {', '.join(have)}")
        for name, value in registry.items():
            if value.missing is not None:
                lines.append(
                    f"{kind} unavailable: {name} ({value.description}; needs {value.missing})"
                )
    return lines


def wilson_interval(successes: int, runs: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927, JASA 22:209)."""
    if runs == 0:
        return 0.0, 1.0
    p = successes / runs
    denom = 1.0 + z * z / runs
    centre = (p + z * z / (2 * runs)) / denom
    half = z * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def _r(value: float | None, digits: int = 3) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def summarise(outcomes: Sequence[Outcome]) -> dict[str, Any]:
    """One table row from the runs of one cell."""
    spec = outcomes[0].spec
    n = len(outcomes)
    wins = [o for o in outcomes if o.success]
    times = [o.time_to_success_s for o in wins if o.time_to_success_s is not None]
    low, high = wilson_interval(len(wins), n)
    q1, med, q3 = (
        (float(v) for v in np.percentile(times, [25, 50, 75])) if times else (None, None, None)
    )
    return {
        "algorithm": spec.algorithm,
        "environment": spec.environment,
        "sensor": spec.sensor,
        "dynamics": spec.dynamics,
        "vehicles": ALGORITHMS[spec.algorithm].vehicles,
        "runs": n,
        "success_rate": _r(len(wins) / n),
        "success_ci95": [_r(low), _r(high)],
        "median_time_s": _r(med, 1),
        "time_iqr_s": [_r(q1, 1), _r(q3, 1)],
        "path_length_m": _r(float(np.median([o.path_length_m for o in outcomes])), 1),
        "path_ratio": _r(
            float(np.median([o.path_length_m / o.initial_distance_m for o in outcomes])), 2
        ),
        "final_error_m": _r(float(np.median([o.final_error_m for o in outcomes])), 2),
        "detections_per_min": _r(float(np.mean([o.detections_per_min for o in outcomes])), 1),
        "declared_rate": _r(sum(o.declared for o in outcomes) / n),
    }


def _fmt(value: float | None, digits: int) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def markdown_table(rows: Sequence[dict[str, Any]]) -> str:
    head = (
        "| algorithm | environment | sensor | runs | success % (95 % CI) | median time s (IQR) "
        "| path m | path / initial distance | final error m | detections / min |\n"
        "|---|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in rows:
        low, high = r["success_ci95"]
        q1, q3 = r["time_iqr_s"]
        time_cell = (
            "–"
            if r["median_time_s"] is None
            else f"{r['median_time_s']:.1f} ({_fmt(q1, 1)}–{_fmt(q3, 1)})"
        )
        lines.append(
            f"| {r['algorithm']} | {r['environment']} | {r['sensor']} | {r['runs']} "
            f"| {100 * r['success_rate']:.0f} ({100 * low:.0f}–{100 * high:.0f}) | {time_cell} "
            f"| {_fmt(r['path_length_m'], 0)} | {_fmt(r['path_ratio'], 2)} "
            f"| {_fmt(r['final_error_m'], 2)} | {_fmt(r['detections_per_min'], 0)} |"
        )
    return head + "\n".join(lines) + "\n"


def _specs(opts: GslOptions) -> list[EpisodeSpec]:
    return [
        EpisodeSpec(
            algorithm=a,
            environment=e,
            sensor=s,
            run=run,
            seed=opts.seed,
            time_limit_s=opts.time_limit_s,
            control_hz=opts.control_hz,
            sensor_period_ticks=opts.sensor_period_ticks,
            keep_trajectory=run == 0,
            dynamics=opts.dynamics,
        )
        for e in opts.environments
        for s in opts.sensors
        for a in opts.algorithms
        for run in range(opts.runs)
    ]


@functools.cache
def _base_scenario() -> Scenario:
    return load_scenario()


def _run(spec: EpisodeSpec) -> Outcome:
    return run_episode(spec, _base_scenario())


def run_all(opts: GslOptions, progress: Callable[[int, int], None] | None = None) -> list[Outcome]:
    """Every episode, in spec order (the order the workers finish in does not matter)."""
    specs = _specs(opts)
    done: list[Outcome] = []
    if opts.jobs <= 1:
        for spec in specs:
            done.append(_run(spec))
            if progress:
                progress(len(done), len(specs))
    else:
        ctx = multiprocessing.get_context("fork")
        with ctx.Pool(opts.jobs) as pool:
            for outcome in pool.imap_unordered(_run, specs, chunksize=1):
                done.append(outcome)
                if progress:
                    progress(len(done), len(specs))
    order = {spec: i for i, spec in enumerate(specs)}
    return sorted(done, key=lambda o: order[o.spec])


def rows_of(opts: GslOptions, outcomes: Sequence[Outcome]) -> list[dict[str, Any]]:
    cells: dict[tuple[str, str, str], list[Outcome]] = {}
    for o in outcomes:
        cells.setdefault((o.spec.algorithm, o.spec.environment, o.spec.sensor), []).append(o)
    return [summarise(cells[key]) for key in cells]


def report_text(opts: GslOptions, rows: Sequence[dict[str, Any]]) -> str:
    """The Markdown report: protocol line, availability, table. No wall-clock content."""
    protocol = (
        f"{opts.runs} runs per cell, seed {opts.seed}, dynamics {opts.dynamics} "
        f"(control {opts.control_hz} Hz, sensor every {opts.sensor_period_ticks} ticks), "
        f"limit {opts.time_limit_s:g} s, starts 30–80 m downwind and ±20 m crosswind at 10 m, "
        "success: declared estimate (or final position) within 2 m of the source."
    )
    avail = "\n".join(f"- {line}" for line in availability_lines())
    return f"{protocol}\n\n{avail}\n\n{markdown_table(rows)}"


def write_outputs(
    out: Path, opts: GslOptions, rows: Sequence[dict[str, Any]], outcomes: Sequence[Outcome]
) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    md = out / "gsl.md"
    md.write_text(report_text(opts, rows))
    js = out / "gsl.json"
    js.write_text(json.dumps(list(rows), indent=1, ensure_ascii=False) + "\n")
    written = [md, js]
    from experiments.gsl_figure import plot_trajectories  # matplotlib only when writing figures

    for env in opts.environments:
        samples = [o for o in outcomes if o.spec.environment == env and o.trajectories]
        written.append(plot_trajectories(out / f"trajectories_{env}.png", env, samples))
    return written
