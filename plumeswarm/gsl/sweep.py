"""``plumeswarm bench gsl sweep PARAM=v1,v2,…``: how the table changes with one parameter.

A parameter is one of

- ``behavior.NAME`` — a class attribute of the behaviours (``behavior.lost_s``): set on every
  algorithm that has it (the others, the floor and ceiling among them, run unchanged);
- ``start.along_m`` — every start this far downwind of the source (the crosswind spread
  stays the protocol's);
- ``section.key`` — any field of the environment's scenario (``wind.meander.preset``,
  ``plume.sources.release_rate_g_s``: a key under a list of sections is set in each).

Each value runs the whole grid on the same starts; one table per parameter. Sweeps are for
tuning, so they run the tuning environments by default and refuse the test seeds (< 1000) and
the published environments unless told otherwise, and then say so loudly in ``sweep.md`` and
``sweep.json``.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from plumeswarm.gsl.bench import (
    TUNING_SEED_MIN,
    GslOptions,
    cells_of,
    command_line,
    protocol_line,
    row_of,
    run_specs,
    specs_of,
)
from plumeswarm.gsl.episode import EpisodeSpec, Outcome
from plumeswarm.gsl.registry import (
    GslError,
    is_published_environment,
    load_environment,
    parse_value,
    tuned_behavior,
    tuning_environment_names,
)

START_PARAM = "start.along_m"


@dataclass(frozen=True)
class SweepParam:
    name: str
    values: tuple[Any, ...]


def parse_sweep(text: str) -> SweepParam:
    """``NAME=v1,v2,…`` → the parameter; :class:`GslError` if malformed."""
    name, sep, values = text.partition("=")
    parts = [v.strip() for v in values.split(",") if v.strip()]
    if not sep or not name or "." not in name or not parts:
        raise GslError(f"sweep {text!r}: expected SECTION.KEY=v1,v2,… (e.g. behavior.lost_s=0.5,1)")
    return SweepParam(name, tuple(parse_value(p) for p in parts))


def tuning_warning(
    opts: GslOptions, allow_test_seeds: bool, allow_test_environments: bool = False
) -> str | None:
    """None for tuning seeds in tuning environments (or scenario files of one's own); a
    warning when test seeds or published environments were allowed; else :class:`GslError`."""
    warnings = []
    if opts.seed < TUNING_SEED_MIN:
        if not allow_test_seeds:
            raise GslError(
                f"--seed {opts.seed}: a sweep tunes, and tuning uses seeds >= {TUNING_SEED_MIN} "
                "(the published tables use seed 0); --allow-test-seeds to sweep them anyway"
            )
        warnings.append(
            f"this sweep used test seeds (seed {opts.seed} < {TUNING_SEED_MIN}): parameters "
            "chosen from it are tuned on the published tables' starts"
        )
    published = [e for e in opts.environments if is_published_environment(e)]
    if published:
        if not allow_test_environments:
            raise GslError(
                f"--environments {','.join(published)}: a sweep tunes, and tuning uses the "
                f"tuning environments ({', '.join(tuning_environment_names())}) or scenario "
                "files of your own, not the published tables' environments; "
                "--allow-test-environments to sweep them anyway"
            )
        warnings.append(
            f"this sweep used the published tables' environments ({', '.join(published)}): "
            "parameters chosen from it are tuned on the test environments"
        )
    return f"WARNING: {'; '.join(warnings)}" if warnings else None


def value_specs(opts: GslOptions, name: str, value: Any) -> list[EpisodeSpec]:
    if name.startswith("behavior."):
        key = name.removeprefix("behavior.")
        configs, tuned = [], 0
        for algo in opts.configs:
            try:
                behavior = tuned_behavior(algo.behavior, {key: value})
                tuned += 1
            except GslError:
                behavior = algo.behavior
            configs.append(dataclasses.replace(algo, behavior=behavior))
        if not tuned:
            # the error of the first asked algorithm names the parameters it has
            tuned_behavior(opts.configs[min(1, len(opts.configs) - 1)].behavior, {key: value})
        return specs_of(dataclasses.replace(opts, configs=tuple(configs)))
    if name == START_PARAM:
        if not isinstance(value, int | float) or not 0 < value <= 1000:
            raise GslError(f"{START_PARAM}={value!r}: metres downwind, in (0, 1000]")
        return specs_of(opts, start_along_m=(float(value), float(value)))
    overrides = (*opts.radio, (name, value))
    for env in opts.environments:
        load_environment(env, overrides)  # GslError: no such field, or a bad value
    return specs_of(opts, overrides=overrides)


Group = tuple[SweepParam, Any, list[EpisodeSpec]]  # a parameter, one of its values, its grid


def sweep_groups(opts: GslOptions, params: Sequence[SweepParam]) -> list[Group]:
    """Every (parameter, value) and its episodes; all of them together are the sweep's grid."""
    if len(opts.radios) > 1:
        raise GslError(f"--radio {opts.radio_text()}: a sweep takes one radio setting")
    return [(p, v, value_specs(opts, p.name, v)) for p in params for v in p.values]


def sweep_tables(groups: Sequence[Group], outcomes: Sequence[Outcome]) -> list[dict[str, Any]]:
    """Every parameter's table: ``{"parameter", "values", "rows"}``; the rows of each value
    carry ``value``. ``outcomes``: those of the groups' specs, in order."""
    tables: dict[str, dict[str, Any]] = {}
    at = 0
    for param, value, specs in groups:
        mine = outcomes[at : at + len(specs)]
        at += len(specs)
        table = tables.setdefault(
            param.name, {"parameter": param.name, "values": list(param.values), "rows": []}
        )
        for cell in cells_of(mine).values():
            row = row_of(cell)
            row["tuned"] = "?" in cell[0].spec.behavior or not param.name.startswith("behavior.")
            table["rows"].append({"parameter": param.name, "value": value, **row})
    return list(tables.values())


def run_sweep(
    opts: GslOptions,
    params: Sequence[SweepParam],
    progress: Callable[[int, int], None] | None = None,
) -> list[dict[str, Any]]:
    """Every parameter's table (:func:`sweep_tables`); all episodes share the worker pool."""
    groups = sweep_groups(opts, params)
    outcomes = run_specs([s for _, _, specs in groups for s in specs], opts.jobs, progress)
    return sweep_tables(groups, outcomes)


def _pct(rate: float, ci: Sequence[float]) -> str:
    return f"{100 * rate:.0f} ({100 * ci[0]:.0f}–{100 * ci[1]:.0f})"


def sweep_table(table: dict[str, Any]) -> str:
    head = (
        f"| algorithm | environment | sensor | {table['parameter']} | success % (95 % CI) "
        "| false declarations % | reached ≤ 2 m % | median time s | final error m |\n"
        "|---|---|---|---|---|---|---|---|---|\n"
    )
    lines = []
    for r in table["rows"]:
        value = json.dumps(r["value"]) if r["tuned"] else f"({json.dumps(r['value'])}: n/a)"
        time = "–" if r["median_time_s"] is None else f"{r['median_time_s']:.1f}"
        lines.append(
            f"| {r['algorithm']} | {r['environment']} | {r['sensor']} | {value} "
            f"| {_pct(r['success_rate'], r['success_ci95'])} "
            f"| {100 * r['false_declaration_rate']:.0f} | {100 * r['reached_2m_rate']:.0f} "
            f"| {time} | {r['final_error_m']:.2f} |"
        )
    return head + "\n".join(lines) + "\n"


def sweep_command(opts: GslOptions, params: Sequence[SweepParam]) -> str:
    args = " ".join(f"{p.name}={','.join(json.dumps(v) for v in p.values)}" for p in params)
    allowed = "".join(
        f" --allow-test-{what}"
        for what, used in (
            ("seeds", opts.seed < TUNING_SEED_MIN),
            ("environments", any(is_published_environment(e) for e in opts.environments)),
        )
        if used
    )
    return command_line(opts, "sweep").replace(" sweep", f" sweep {args}", 1) + allowed


def sweep_report(
    opts: GslOptions,
    params: Sequence[SweepParam],
    tables: Sequence[dict[str, Any]],
    warning: str | None,
) -> str:
    command = sweep_command(opts, params)
    text = f"```\n{command}\n```\n\n"
    if warning:
        text += f"**{warning}**\n\n"
    text += f"{protocol_line(opts)}\n"
    for table in tables:
        text += f"\n### {table['parameter']}\n\n{sweep_table(table)}"
    return text


def write_sweep(
    out: Path,
    opts: GslOptions,
    params: Sequence[SweepParam],
    tables: Sequence[dict[str, Any]],
    warning: str | None,
) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / "sweep.md", out / "sweep.json"
    md.write_text(sweep_report(opts, params, tables, warning))
    document = {"seed": opts.seed, "runs": opts.runs, "warning": warning, "tables": list(tables)}
    js.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n")
    return [md, js]
