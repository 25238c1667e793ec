"""The command line's help: every option of every command says what it does, and the bench's
internal stand-in roles (``ceiling-*``) are accepted by ``node`` but never shown."""

from __future__ import annotations

from collections.abc import Iterator

import click

from deploy.roles import BENCH_ROLES, ROLES
from plumeswarm.cli.main import cli
from tests.support.procs import run_cli


def _options(command: click.Command, path: str) -> Iterator[tuple[str, click.Option]]:
    """Every option of ``command`` and of its subcommands, with the command's full name."""
    for param in command.params:
        if isinstance(param, click.Option):
            yield path, param
    if isinstance(command, click.Group):
        for name, sub in command.commands.items():
            yield from _options(sub, f"{path} {name}")


def test_every_option_of_every_command_has_help_text() -> None:
    seen = list(_options(cli, "plumeswarm"))
    commands = {path for path, _ in seen}
    # the walk reaches the nested groups too (a walk that stops at the top passes vacuously)
    assert {"plumeswarm up", "plumeswarm bench scale", "plumeswarm bench gsl sweep"} <= commands
    missing = [f"{path} {'/'.join(opt.opts)}" for path, opt in seen if not (opt.help or "").strip()]
    assert missing == [], f"options without help text: {', '.join(missing)}"


def test_node_help_lists_the_roles_but_not_the_bench_stand_ins() -> None:
    res = run_cli(["node", "--help"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    assert all(role in res.stdout for role in ROLES), res.stdout
    assert "ceiling" not in res.stdout, res.stdout


def test_an_unknown_role_lists_the_public_roles_only() -> None:
    res = run_cli(["node", "nosuch"], timeout_s=60)
    assert res.returncode == 2
    assert all(role in res.stderr for role in ROLES), res.stderr
    assert "ceiling" not in res.stderr, res.stderr


def test_a_bench_stand_in_role_is_still_accepted() -> None:
    """``ceiling-autopilot`` passes the role choice: what stops it is the missing vehicle, the
    check that comes after the choice."""
    assert "ceiling-autopilot" in BENCH_ROLES
    res = run_cli(["node", "ceiling-autopilot"], timeout_s=60)
    assert res.returncode == 2
    assert "needs --vehicle ID" in res.stderr, res.stderr
    assert "Invalid value" not in res.stderr, res.stderr
