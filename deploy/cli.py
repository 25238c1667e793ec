"""The ``plumeswarm`` command line. Argument parsing lives only here (click)."""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import NoReturn

import click

from deploy.roles import ROLES, RoleUnavailable, role_entry
from swarmbus.scenario import Scenario, ScenarioError, load_scenario, resolve_scenario_path

log = logging.getLogger(__name__)


def fail(message: str, code: int = 2) -> NoReturn:
    """One clear line on stderr and a non-zero exit: never a traceback."""
    click.echo(f"plumeswarm: error: {message}", err=True)
    sys.exit(code)


def not_yet(what: str, issue: str) -> NoReturn:
    fail(f"'{what}' is not implemented yet (issue {issue})")


def scenario_from(name_or_path: str | None) -> Scenario:
    try:
        return load_scenario(resolve_scenario_path(name_or_path))
    except ScenarioError as exc:
        fail(str(exc))


def setup_logging(verbose: int) -> None:
    level = logging.WARNING - 10 * verbose
    logging.basicConfig(
        level=max(level, logging.DEBUG),
        format="%(asctime)s %(name)s %(levelname)s: %(message)s",
        stream=sys.stderr,
    )


SCENARIO_OPT = click.option(
    "--scenario",
    "-s",
    "scenario",
    default=None,
    metavar="FILE|NAME",
    help="Scenario file or bundled scenario name (default: novak2018).",
)


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
@click.version_option(package_name="plumeswarm")
def cli(verbose: int) -> None:
    """plumeswarm: a Zenoh-distributed UAV swarm simulator in a gas plume."""
    setup_logging(verbose)


# ---------------------------------------------------------------------------- scenario
@cli.group()
def scenario() -> None:
    """Validate and inspect scenario files."""


@scenario.command("check")
@click.argument("file", type=click.Path(dir_okay=True, path_type=Path))
def scenario_check(file: Path) -> None:
    """Validate FILE; print a one-line summary, or one line naming the bad field."""
    sc = scenario_from(str(file))
    click.echo(
        f"{file}: ok — world {sc.world.name!r}, {len(sc.vehicles)} vehicle(s), "
        f"physics {sc.time.physics_hz} Hz / control {sc.time.control_hz} Hz, "
        f"{sc.time.mode}"
    )


# ---------------------------------------------------------------------------- node
@cli.command()
@click.argument("role", type=click.Choice(sorted(ROLES)))
@SCENARIO_OPT
@click.option("--vehicle", "vehicles", multiple=True, help="Vehicle id(s) this node serves.")
@click.option("--name", default=None, help="Node name on the bus (default: derived from role).")
@click.option("--connect", multiple=True, help="Zenoh endpoint to connect to (repeatable).")
@click.option("--listen", multiple=True, help="Zenoh endpoint to listen on (repeatable).")
@click.option("--mode", type=click.Choice(["peer", "client", "router"]), default=None)
@click.option("--set", "options", multiple=True, metavar="KEY=VALUE", help="Role option.")
def node(
    role: str,
    scenario: str | None,
    vehicles: tuple[str, ...],
    name: str | None,
    connect: tuple[str, ...],
    listen: tuple[str, ...],
    mode: str | None,
    options: tuple[str, ...],
) -> None:
    """Run one ROLE alone (for deployments across machines)."""
    from swarmbus.keys import KeyNameError, check_name
    from swarmbus.node import NodeContext

    sc = scenario_from(scenario)
    known = {v.id for v in sc.vehicles}
    for vid in vehicles:
        if vid not in known:
            fail(f"--vehicle {vid!r} is not in the scenario (vehicles: {', '.join(sorted(known))})")
    if role == "autopilot" and not vehicles:
        fail("role 'autopilot' needs --vehicle ID")
    opts: dict[str, str] = {}
    for item in options:
        key, sep, value = item.partition("=")
        if not sep or not key:
            fail(f"--set expects KEY=VALUE, got {item!r}")
        opts[key] = value
    node_name = name or (f"{role}-{'-'.join(vehicles)}" if vehicles else role)
    try:
        check_name("node", node_name)
    except KeyNameError as exc:
        fail(str(exc))
    net = sc.network.with_overrides(
        mode=mode, connect=list(connect) or None, listen=list(listen) or None
    )
    try:
        entry = role_entry(role)
    except RoleUnavailable as exc:
        fail(str(exc))
    ctx = NodeContext(sc, net, node_name, tuple(vehicles), opts)
    sys.exit(entry(ctx))


# ---------------------------------------------------------------------------- the rest
@cli.command(context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def up() -> None:
    """Start the whole swarm (plume, physics, autopilots, gateway, viewer) and supervise it."""
    not_yet("plumeswarm up", "#7")


@cli.command(context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def demo() -> None:
    """Fly the default scenario end to end, headless, and print the accuracy table."""
    not_yet("plumeswarm demo", "#7")


@cli.command(context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def status() -> None:
    """Ask the bus what is running: nodes, sim time, vehicles."""
    not_yet("plumeswarm status", "#7")


@cli.command()
@SCENARIO_OPT
@click.option("--connect", multiple=True, help="Zenoh endpoint to connect to (repeatable).")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None)
def record(scenario: str | None, connect: tuple[str, ...], out: Path | None) -> None:
    """Record everything on the bus to an MCAP file (until Ctrl-C)."""
    from deploy.recording import commands

    sys.exit(commands.record(scenario_from(scenario), list(connect), out))


@cli.command()
@click.argument("file")
@click.option("--speed", type=float, default=1.0, show_default=True, help="Time scale factor.")
@SCENARIO_OPT
@click.option("--connect", multiple=True, help="Zenoh endpoint to connect to (repeatable).")
@click.option("--wait-for", multiple=True, metavar="NODE", help="Start once NODE is on the bus.")
@click.option("--recorded-by", default=None, metavar="NODE", help="Recorder to hand-shake with.")
def replay(
    file: str,
    speed: float,
    scenario: str | None,
    connect: tuple[str, ...],
    wait_for: tuple[str, ...],
    recorded_by: str | None,
) -> None:
    """Publish a recording back onto the bus with its timing."""
    from deploy.recording import commands

    sc = scenario_from(scenario)
    sys.exit(commands.replay(file, sc, list(connect), speed, wait_for, recorded_by))


@cli.command()
@click.argument("file")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
def report(file: str, out: Path) -> None:
    """Plots, CSV and a one-page report from a recording."""
    from deploy.recording import commands

    sys.exit(commands.report(file, out))


@cli.command(context_settings={"ignore_unknown_options": True, "allow_extra_args": True})
def bench() -> None:
    """Scale benchmark of the full stack."""
    not_yet("plumeswarm bench", "#10")


def _register_groups() -> None:
    from deploy.plume_cli import plume

    cli.add_command(plume)


_register_groups()


def main() -> None:
    cli(prog_name="plumeswarm")


if __name__ == "__main__":
    main()
