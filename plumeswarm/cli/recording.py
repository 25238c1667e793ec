"""The bodies of ``plumeswarm record``, ``replay`` and ``report`` (their options are parsed in
:mod:`plumeswarm.cli.main`).

Each returns the process exit code; failures are one line on stderr, never a traceback.
"""

from __future__ import annotations

from pathlib import Path

import click

from swarmbus.node import NodeContext
from swarmbus.options import role_options
from swarmbus.scenario import Scenario


def _context(
    scenario: Scenario, connect: list[str], name: str, options: dict[str, str]
) -> NodeContext:
    net = scenario.network.with_overrides(connect=connect or None)
    return NodeContext(scenario, net, name, (), options)


def record(scenario: Scenario, connect: list[str], out: Path | None) -> int:
    """Run the recorder in the foreground until Ctrl-C / SIGTERM."""
    from recorder.node import RecorderOptions, main

    ctx = _context(scenario, connect, "recorder", {"out": str(out)} if out else {})
    target = Path(role_options(RecorderOptions, ctx).out)
    ctx = _context(scenario, connect, "recorder", {"out": str(target)})
    problem = _unwritable(target)
    if problem:
        click.echo(f"plumeswarm: error: cannot record to {target}: {problem}", err=True)
        return 2
    click.echo(f"recording world {scenario.world.name!r} to {target} (Ctrl-C to stop)", err=True)
    code = main(ctx)
    if code == 0:
        click.echo(f"recorded {target}", err=True)
    else:
        click.echo(f"plumeswarm: error: cannot record to {target} (see the log above)", err=True)
    return code


def _unwritable(target: Path) -> str:
    """Why a recording cannot be written at ``target`` ("" when it can, as far as we can tell)."""
    if target.is_dir():
        return "is a directory"
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        return exc.strerror or str(exc)
    if not target.parent.is_dir():
        return f"{target.parent} is not a directory"
    return ""


def replay(
    path: str,
    scenario: Scenario,
    connect: list[str],
    speed: float,
    wait_for: tuple[str, ...],
    recorded_by: str | None,
) -> int:
    """Publish a recording back onto the bus; one line on success or failure."""
    from recorder import replay as rp
    from recorder.reader import RecordingError

    opts = rp.ReplayOptions(speed=speed, wait_for=wait_for, recorded_by=recorded_by)
    try:
        sent = rp.run(path, scenario, connect, opts)
    except (RecordingError, rp.ReplayError) as exc:
        click.echo(f"plumeswarm: error: {exc}", err=True)
        return 2
    click.echo(f"replayed {sent} messages from {path}", err=True)
    return 0


def report(path: str, out: Path) -> int:
    """Write the report of a recording; one line on success or failure."""
    from recorder.reader import RecordingError
    from recorder.report import ReportError, make_report

    try:
        files = make_report(path, out)
    except (RecordingError, ReportError) as exc:
        click.echo(f"plumeswarm: error: {exc}", err=True)
        return 2
    except OSError as exc:
        click.echo(f"plumeswarm: error: cannot write the report to {out}: {exc}", err=True)
        return 2
    click.echo(f"wrote {len(files)} files to {out} (open {out / 'report.html'})", err=True)
    return 0
