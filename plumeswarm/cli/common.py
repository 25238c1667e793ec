"""What every ``plumeswarm`` command module shares: one-line failures, loading a scenario, and the
options several commands take."""

from __future__ import annotations

import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any, NoReturn

import click

from swarmbus.scenario import Scenario, ScenarioError, load_scenario, resolve_scenario_path


def fail(message: str, code: int = 2) -> NoReturn:
    """One clear line on stderr and a non-zero exit: never a traceback."""
    click.echo(f"plumeswarm: error: {message}", err=True)
    sys.exit(code)


SET_OPT = click.option(
    "--set",
    "scenario_overrides",
    multiple=True,
    metavar="SECTION.KEY=VALUE",
    help="Override one scenario value (repeatable), e.g. --set sensor.preset=pid "
    "--set wind.speed_m_s=4 (a TOML value; text is taken as a string).",
)


def scenario_from(name_or_path: str | None, overrides: tuple[str, ...] = ()) -> Scenario:
    try:
        return load_scenario(resolve_scenario_path(name_or_path), overrides)
    except ScenarioError as exc:
        fail(str(exc))


def scenario_file(
    name_or_path: str | None, overrides: tuple[str, ...], run_dir: Path
) -> tuple[Scenario, Path]:
    """The scenario and the file every process of a run reads: the named file itself, or, with
    overrides, the overridden scenario written to ``run_dir/scenario.toml``."""
    path = resolve_scenario_path(name_or_path)
    sc = scenario_from(str(path), overrides)
    if overrides:
        from deploy.scaling import write_scenario

        path = write_scenario(sc, run_dir / "scenario.toml")
    return sc, path


Decorator = Callable[[Callable[..., Any]], Callable[..., Any]]

connect_option: Decorator = click.option(
    "--connect", multiple=True, help="Zenoh endpoint to connect to (repeatable)."
)


def vehicles_per_process_option(help_text: str | None = None) -> Decorator:
    """``--vehicles-per-process N`` (at least 1, default 1)."""
    return click.option(
        "--vehicles-per-process",
        type=click.IntRange(min=1),
        default=1,
        show_default=True,
        help=help_text,
    )


def out_dir_option(help_text: str | None = None) -> Decorator:
    """``--out DIR``, a directory (default None: the command names one)."""
    return click.option(
        "--out", type=click.Path(file_okay=False, path_type=Path), default=None, help=help_text
    )


SCENARIO_OPT = click.option(
    "--scenario",
    "-s",
    "scenario",
    default=None,
    metavar="FILE|NAME",
    help="Scenario file or bundled scenario name, as `plumeswarm scenario list` names them "
    "(default: novak2018).",
)


def comma_list(value: str) -> tuple[str, ...]:
    """A comma-separated list's items; a comma inside brackets or braces (a tuned
    algorithm's JSON parameters, ``name=module:Class?{"a":1,"b":2}``) separates nothing."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(value):
        if ch in "{[(":
            depth += 1
        elif ch in "}])":
            depth = max(depth - 1, 0)
        elif ch == "," and depth == 0:
            items.append(value[start:i])
            start = i + 1
    items.append(value[start:])
    return tuple(v.strip() for v in items if v.strip())
