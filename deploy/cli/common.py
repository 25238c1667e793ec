"""What every ``plumeswarm`` command module shares: one-line failures and loading a scenario."""

from __future__ import annotations

import sys
from typing import NoReturn

import click

from swarmbus.scenario import Scenario, ScenarioError, load_scenario, resolve_scenario_path


def fail(message: str, code: int = 2) -> NoReturn:
    """One clear line on stderr and a non-zero exit: never a traceback."""
    click.echo(f"plumeswarm: error: {message}", err=True)
    sys.exit(code)


def scenario_from(name_or_path: str | None) -> Scenario:
    try:
        return load_scenario(resolve_scenario_path(name_or_path))
    except ScenarioError as exc:
        fail(str(exc))
