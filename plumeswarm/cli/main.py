"""The ``plumeswarm`` command line. Argument parsing lives only in :mod:`plumeswarm.cli` (click)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from deploy.roles import BENCH_ROLES, ROLES, RoleUnavailable, role_entry
from plumeswarm.cli.common import (
    SCENARIO_OPT,
    SET_OPT,
    Decorator,
    comma_list,
    connect_option,
    fail,
    scenario_file,
    scenario_from,
    vehicles_per_process_option,
)
from swarmbus.errors import PlumeswarmError
from swarmbus.extras import missing_extra_message
from swarmbus.scenario import Scenario
from swarmbus.session import NetworkConfig

log = logging.getLogger(__name__)


def setup_logging(verbose: int) -> None:
    level = logging.WARNING - 10 * verbose
    logging.basicConfig(
        level=max(level, logging.DEBUG),
        format="%(asctime)s %(name)s %(levelname)s: %(message)s",
        stream=sys.stderr,
    )


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
@click.version_option(package_name="plumeswarm")
def cli(verbose: int) -> None:
    """plumeswarm: a Zenoh-distributed UAV swarm simulator in a gas plume."""
    setup_logging(verbose)


HOSTS_FILE_OPT = click.option(
    "--hosts",
    "hosts_file",
    type=click.Path(path_type=Path),
    default=None,
    help="Hosts file of a deployment (with [tls]: this process's certificate and the ACL).",
)
HOST_OPT = click.option("--host", "host_name", default=None, help="This host's entry in --hosts.")


def secured(
    sc: Scenario,
    net: NetworkConfig,
    hosts_file: Path | None,
    host_name: str | None,
    role: str,
    node_name: str | None = None,
) -> NetworkConfig:
    """``net`` as ``role`` on ``host_name`` of the deployment (TLS identity and ACL), if any;
    its TLS files checked (one line naming a missing or unreadable one)."""
    from swarmbus.session import NetworkConfigError, check_tls_files

    if hosts_file is not None or host_name is not None:
        net = _as_deployed(sc, net, hosts_file, host_name, role, node_name)
    if net.tls is not None:  # also a scenario's own [network.tls]
        try:
            check_tls_files(net.tls)
        except NetworkConfigError as exc:
            fail(str(exc))
    return net


def _as_deployed(
    sc: Scenario,
    net: NetworkConfig,
    hosts_file: Path | None,
    host_name: str | None,
    role: str,
    node_name: str | None,
) -> NetworkConfig:
    from deploy.hosts import HostsError, load_deployment
    from deploy.security import secure_network
    from swarmbus.keys import Keys

    if hosts_file is None or host_name is None:
        fail("--hosts FILE and --host NAME go together")
    try:
        dep = load_deployment(hosts_file)
        if net.connect == sc.network.connect:  # not given: the deployment's router
            net = net.with_overrides(connect=[dep.router])
        listen = dep.host(host_name).listen
        if net.listen == sc.network.listen and listen:  # not given: the host's, as `up` does
            net = net.with_overrides(listen=list(listen))  # (never plain TCP beside mTLS)
        return secure_network(net, dep, host_name, role, Keys(sc.world.name), node_name)
    except HostsError as exc:
        fail(str(exc))


# ---------------------------------------------------------------------------- scenario
@cli.group()
def scenario() -> None:
    """Validate and inspect scenario files."""


@scenario.command("check")
@click.argument("file", metavar="FILE|NAME", type=click.Path(dir_okay=True, path_type=Path))
@SET_OPT
def scenario_check(file: Path, scenario_overrides: tuple[str, ...]) -> None:
    """Validate FILE (or a bundled scenario's NAME, as `scenario list` shows it); print a
    one-line summary, or one line naming the bad field, its value and the valid values."""
    sc = scenario_from(str(file), scenario_overrides)
    click.echo(
        f"{file}: ok — world {sc.world.name!r}, {len(sc.vehicles)} vehicle(s), "
        f"physics {sc.time.physics_hz} Hz / control {sc.time.control_hz} Hz, "
        f"{sc.time.mode}"
    )


@scenario.command("list")
@click.option(
    "--dir",
    "directory",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="List the scenario files (*.toml) of this directory instead of the bundled ones.",
)
def scenario_list(directory: Path | None) -> None:
    """The bundled scenarios, then the benchmark environments as gsl/NAME (NAME alone also
    names one), or DIR's scenarios: one a line, name, vehicles, plume, first comment line."""
    from deploy.scenario_catalog import catalog

    try:
        lines = catalog(directory)
    except ValueError as exc:
        fail(str(exc))
    for line in lines:
        click.echo(line)


@scenario.command("show")
@click.argument("name", metavar="NAME|FILE")
@SET_OPT
def scenario_show(name: str, scenario_overrides: tuple[str, ...]) -> None:
    """The scenario as plumeswarm reads it, every default filled in, as TOML."""
    from deploy.scaling import scenario_toml

    click.echo(scenario_toml(scenario_from(name, scenario_overrides)), nl=False)


@scenario.command("schema")
def scenario_schema() -> None:
    """The JSON Schema of a scenario file (its sections, fields, types and bounds)."""
    import json

    import msgspec

    click.echo(json.dumps(msgspec.json.schema(Scenario), indent=2))


# ---------------------------------------------------------------------------- node
class RoleChoice(click.Choice[str]):
    """The roles: the public ones in help, completion and errors; the bench's stand-ins
    (``ceiling-*``, internal) accepted when given but never shown."""

    def __init__(self, shown: list[str], hidden: list[str]) -> None:
        super().__init__(shown)
        self.hidden = frozenset(hidden)

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None) -> Any:
        if value in self.hidden:
            return value
        return super().convert(value, param, ctx)


@cli.command(
    help=f"Run one ROLE alone (for deployments across machines). ROLE: {', '.join(sorted(ROLES))}."
)
@click.argument("role", metavar="ROLE", type=RoleChoice(sorted(ROLES), sorted(BENCH_ROLES)))
@SCENARIO_OPT
@click.option("--vehicle", "vehicles", multiple=True, help="Vehicle id(s) this node serves.")
@click.option("--name", default=None, help="Node name on the bus (default: derived from role).")
@connect_option
@click.option("--listen", multiple=True, help="Zenoh endpoint to listen on (repeatable).")
@click.option(
    "--mode",
    type=click.Choice(["peer", "client", "router"]),
    default=None,
    help="Zenoh mode of this node (default: the scenario's network.mode).",
)
@click.option("--set", "options", multiple=True, metavar="KEY=VALUE", help="Role option.")
@HOSTS_FILE_OPT
@HOST_OPT
def node(
    role: str,
    scenario: str | None,
    vehicles: tuple[str, ...],
    name: str | None,
    connect: tuple[str, ...],
    listen: tuple[str, ...],
    mode: str | None,
    options: tuple[str, ...],
    hosts_file: Path | None,
    host_name: str | None,
) -> None:
    from swarmbus.keys import KeyNameError, check_name, process_node
    from swarmbus.node import NodeContext
    from swarmbus.options import OptionError, split_settings

    sc = scenario_from(scenario)
    known = {v.id for v in sc.vehicles}
    for vid in vehicles:
        if vid not in known:
            fail(f"--vehicle {vid!r} is not in the scenario (vehicles: {', '.join(sorted(known))})")
    if role in ("autopilot", "ceiling-autopilot") and not vehicles:
        fail("role 'autopilot' needs --vehicle ID")
    try:
        opts = split_settings(options)
    except OptionError as exc:
        fail(str(exc))
    node_name = name or process_node(role, vehicles)
    try:
        check_name("node", node_name)
    except KeyNameError as exc:
        fail(str(exc))
    net = sc.network.with_overrides(
        mode=mode, connect=list(connect) or None, listen=list(listen) or None
    )
    net = secured(sc, net, hosts_file, host_name, role, node_name)
    if net.access_control and net.access_control.get("enabled", True):
        from swarmbus.refusals import watch

        watch()  # each message its ACL refuses: one warning line (docs/deploy.md)
    try:
        entry = role_entry(role)
    except RoleUnavailable as exc:
        fail(str(exc))
    ctx = NodeContext(sc, net, node_name, tuple(vehicles), opts)
    sys.exit(entry(ctx))


# ---------------------------------------------------------------------------- the rest
def _optional_role(flag: tuple[str, str, str], value: tuple[str, click.IntRange, str]) -> Decorator:
    """A role ``up`` adds on request: its flag (``--NAME``, to a boolean ``dest``) and the flag of
    its one option (no default; giving it implies the role), each with its help."""
    name, dest, flag_help = flag
    value_flag, value_type, value_help = value

    def apply(f: Callable[..., Any]) -> Callable[..., Any]:
        f = click.option(value_flag, type=value_type, default=None, help=value_help)(f)
        return click.option(name, dest, is_flag=True, help=flag_help)(f)

    return apply


@cli.command()
@click.argument("scenario_arg", metavar="[SCENARIO]", required=False)
@SCENARIO_OPT
@click.option("--headless", is_flag=True, help="No viewer.")
@click.option("--record", is_flag=True, help="Also run the recorder (MCAP in the run directory).")
@_optional_role(
    ("--foxglove", "foxglove_live", "Also serve the run live to Foxglove (WebSocket on "
     "127.0.0.1)."),
    ("--foxglove-port", click.IntRange(0, 65535), "Port of the live Foxglove server (implies "
     "--foxglove; default 8765, 0: any free)."),
)  # fmt: skip
@_optional_role(
    ("--ros2", "ros2_bridge", "Also run the ROS 2 bridge: the run as ROS 2 topics for rmw_zenoh "
     "(docs/ros2.md)."),
    ("--ros2-domain", click.IntRange(0, 232), "ROS domain id of the bridge (implies --ros2; "
     "default: ROS_DOMAIN_ID, else 0)."),
)  # fmt: skip
@click.option("--out", type=click.Path(path_type=Path), default=None, help="Run directory.")
@click.option("--connect", multiple=True, help="Router endpoint (default: the scenario's).")
@click.option("--listen", multiple=True, help="Endpoint every node listens on.")
@click.option("--roles", default=None, help="Only these roles, comma-separated (one host of many).")
@click.option("--no-router", is_flag=True, help="Do not start a router (another host runs it).")
@HOSTS_FILE_OPT
@HOST_OPT
@vehicles_per_process_option("Vehicles each autopilot process serves.")
@click.option(
    "--stepped",
    is_flag=True,
    help="Stepped clock: the world advances only when one client steps it (Swarm.step).",
)
@click.option(
    "--insecure",
    is_flag=True,
    help="Start the gateway even with a MAVLink link beyond loopback and no signing key.",
)
@SET_OPT
def up(
    scenario_arg: str | None,
    scenario: str | None,
    headless: bool,
    record: bool,
    foxglove_live: bool,
    foxglove_port: int | None,
    ros2_bridge: bool,
    ros2_domain: int | None,
    out: Path | None,
    connect: tuple[str, ...],
    listen: tuple[str, ...],
    roles: str | None,
    no_router: bool,
    hosts_file: Path | None,
    host_name: str | None,
    vehicles_per_process: int,
    stepped: bool,
    insecure: bool,
    scenario_overrides: tuple[str, ...],
) -> None:
    """Start the whole swarm (plume, physics, autopilots, gateway, viewer) and supervise it."""
    from deploy.console import Console
    from deploy.hosts import HostsError, load_deployment, options_for_host
    from deploy.launcher import LaunchError, LaunchOptions, default_run_dir, selected_roles
    from deploy.security import secure_launch
    from deploy.up import run_up
    from plumeswarm.experiments.launch import NODE_COMMAND
    from swarmbus.keys import Keys

    try:
        deployment = load_deployment(hosts_file) if hosts_file is not None else None
    except HostsError as exc:
        fail(str(exc))
    run_dir = out or default_run_dir()
    sc, path = scenario_file(
        scenario_arg or scenario or (deployment.scenario if deployment else None),
        scenario_overrides,
        run_dir,
    )
    secured(sc, sc.network, None, None, "operator")  # its TLS files, if any, are readable
    if stepped:  # every process reads the mode from the scenario: fly a stepped copy of it
        import msgspec

        from deploy.scaling import write_scenario

        sc = msgspec.structs.replace(sc, time=msgspec.structs.replace(sc.time, mode="stepped"))
        path = write_scenario(sc, run_dir / "scenario-stepped.toml")
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=headless,
        record=record,
        run_dir=run_dir,
        connect=connect,
        listen=listen,
        roles=comma_list(roles) if roles else None,
        router=not no_router,
        vehicles_per_process=vehicles_per_process,
        foxglove=foxglove_live or foxglove_port is not None,
        ros2=ros2_bridge or ros2_domain is not None,
        node_options=_up_node_options(foxglove_port, ros2_domain),
    )
    if deployment is not None or host_name is not None:
        try:
            opts = options_for_host(opts, deployment, host_name)
            assert deployment is not None and hosts_file is not None and host_name is not None
            keys = Keys(sc.world.name)
            opts = secure_launch(opts, deployment, hosts_file, host_name, sc.network, keys)
        except HostsError as exc:
            fail(str(exc))
    try:
        if "gateway" in selected_roles(opts):
            _check_mavlink_exposure(sc, insecure)
        sys.exit(run_up(sc, opts, Console()))
    except LaunchError as exc:
        fail(str(exc), code=1)


def _check_mavlink_exposure(sc: Scenario, insecure: bool) -> None:
    """Refuse a gateway link beyond loopback without signing unless ``insecure`` (then one
    warning line)."""
    from gcs_bridge.options import GatewayOptions, exposure_note, unsigned_exposed
    from swarmbus.options import OptionError

    try:
        exposed = unsigned_exposed(sc.gateway, GatewayOptions.defaults(sc))
    except OptionError as exc:
        fail(f"gateway: {exc}")
    if exposed and not insecure:
        fail(f"{exposure_note(exposed)} (or --insecure)")
    if exposed:
        click.echo(f"plumeswarm: warning: {exposure_note(exposed)}", err=True)


def _up_node_options(
    foxglove_port: int | None, ros2_domain: int | None
) -> dict[str, tuple[str, ...]]:
    out: dict[str, tuple[str, ...]] = {}
    if foxglove_port is not None:
        out["foxglove"] = (f"port={foxglove_port}",)
    if ros2_domain is not None:
        out["ros2"] = (f"domain_id={ros2_domain}",)
    return out


@cli.command()
@SCENARIO_OPT
@click.option("--vehicles", type=click.IntRange(1, 1024), default=None, help="Scale to N vehicles.")
@click.option("--out", type=click.Path(path_type=Path), default=None, help="Run directory.")
@click.option(
    "--timeout",
    "timeout_s",
    type=float,
    default=900.0,
    show_default=True,
    help="Wall seconds the flight may take; past them the demo stops and reports what it flew.",
)
@click.option("--attach", multiple=True, metavar="EP", help="Fly a stack already running here.")
@click.option(
    "--record/--no-record", default=True, help="Record the run (when the recorder exists)."
)
@click.option(
    "--clock",
    type=click.Choice(["stepped", "lockstep", "realtime"]),
    default=None,
    help="stepped (default): the demo steps the clock, two runs give the same state digest; "
    "lockstep: free-running, as fast as the slowest process; realtime: paced to the wall "
    "clock. With --attach the default is however the attached world runs.",
)
@HOSTS_FILE_OPT
@HOST_OPT
@SET_OPT
def demo(
    scenario: str | None,
    vehicles: int | None,
    out: Path | None,
    timeout_s: float,
    attach: tuple[str, ...],
    record: bool,
    clock: str | None,
    hosts_file: Path | None,
    host_name: str | None,
    scenario_overrides: tuple[str, ...],
) -> None:
    """Fly the default scenario end to end, headless, and print the accuracy table."""
    from deploy.console import Console
    from deploy.launcher import default_run_dir
    from plumeswarm.experiments.demo import DemoOptions, run_demo

    run_dir = out or default_run_dir()
    sc, path = scenario_file(scenario, scenario_overrides, run_dir)
    if (hosts_file or host_name) and not attach:
        fail("--hosts/--host go with --attach (the demo joins that deployment as its operator)")
    net = secured(sc, sc.network, hosts_file, host_name, "operator")
    opts = DemoOptions(
        sc,
        path,
        run_dir,
        vehicles,
        timeout_s,
        attach=attach,
        record=record,
        network=net,
        clock=clock,
    )
    from deploy.scaling import ScalingError

    try:
        code = run_demo(opts, Console())
    except ScalingError as exc:  # --vehicles beyond a scenario with a plane
        fail(str(exc))
    sys.exit(code)


@cli.command()
@SCENARIO_OPT
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@click.option("--connect", multiple=True, help="Router endpoint (default: the scenario's).")
@click.option(
    "--timeout",
    "timeout_s",
    type=float,
    default=5.0,
    show_default=True,
    help="Wall seconds to wait for answers from the bus.",
)
@HOSTS_FILE_OPT
@HOST_OPT
def status(
    scenario: str | None,
    as_json: bool,
    connect: tuple[str, ...],
    timeout_s: float,
    hosts_file: Path | None,
    host_name: str | None,
) -> None:
    """Ask the bus what is running: nodes, sim time, vehicles."""
    import json

    from deploy.status import NothingRunning, format_status, query_status
    from swarmbus.keys import Keys

    sc = scenario_from(scenario)
    net = sc.network.with_overrides(connect=list(connect) or None)
    net = secured(sc, net, hosts_file, host_name, "operator")
    try:
        snap = query_status(net, Keys(sc.world.name), [v.id for v in sc.vehicles], timeout_s)
    except NothingRunning as exc:
        fail(str(exc), code=1)
    click.echo(json.dumps(snap.to_json(), indent=2) if as_json else format_status(snap))


@cli.command()
@SCENARIO_OPT
@connect_option
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="MCAP file to write (default: recording.mcap in the current directory).",
)
def record(scenario: str | None, connect: tuple[str, ...], out: Path | None) -> None:
    """Record everything on the bus to an MCAP file (until Ctrl-C)."""
    from plumeswarm.cli import recording as commands

    sys.exit(commands.record(scenario_from(scenario), list(connect), out))


@cli.command()
@click.argument("file")
@click.option("--speed", type=float, default=1.0, show_default=True, help="Time scale factor.")
@SCENARIO_OPT
@connect_option
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
    from plumeswarm.cli import recording as commands

    sc = scenario_from(scenario)
    sys.exit(commands.replay(file, sc, list(connect), speed, wait_for, recorded_by))


@cli.command()
@click.argument("file")
@click.option(
    "--out",
    required=True,
    type=click.Path(file_okay=False, path_type=Path),
    help="Directory to write the plots, CSV and report to.",
)
def report(file: str, out: Path) -> None:
    """Plots, CSV and a one-page report from a recording."""
    from plumeswarm.cli import recording as commands

    sys.exit(commands.report(file, out))


@cli.group()
def export() -> None:
    """Convert a recording for other tools."""


@export.command("foxglove")
@click.argument("src", metavar="IN")
@click.argument("dst", metavar="OUT", type=click.Path(path_type=Path))
@click.option(
    "--layout",
    "layout_file",
    type=click.Path(dir_okay=False, path_type=Path),
    default=None,
    help="Also write a Foxglove layout for the recording's vehicles to this file.",
)
def export_foxglove(src: str, dst: Path, layout_file: Path | None) -> None:
    """Write OUT: recording IN with its Foxglove channels (3D scene, map, plots) made anew."""
    from recorder.foxglove.export import export_foxglove as run_export
    from recorder.foxglove.layout import layout_json
    from recorder.reader import ExportError, RecordingError

    try:
        done = run_export(src, dst, lambda n: click.echo(f"  {n} messages", err=True))
    except (RecordingError, ExportError) as exc:
        fail(str(exc))
    if layout_file is not None:
        try:
            layout_file.write_text(layout_json(done.vehicle_ids))
        except OSError as exc:
            fail(f"cannot write the layout {layout_file}: {exc.strerror or exc}")
    cut = " (IN was cut short: read to its last complete chunk)" if done.truncated else ""
    click.echo(
        f"wrote {dst}: {done.copied} messages copied, {done.foxglove} Foxglove messages{cut}",
        err=True,
    )


@export.command("ros2")
@click.argument("src", metavar="IN")
@click.argument("dst", metavar="OUT_DIR", type=click.Path(path_type=Path))
def export_ros2(src: str, dst: Path) -> None:
    """Write OUT_DIR: recording IN as a rosbag2 (MCAP storage) with the ROS 2 bridge's topics,
    stamped in sim time (docs/ros2.md)."""
    from deploy.ros2_export import export_ros2 as run_export
    from recorder.reader import ExportError, RecordingError

    try:
        done = run_export(src, dst)
    except (RecordingError, ExportError) as exc:
        fail(str(exc))
    cut = " (IN was cut short: read to its last complete chunk)" if done.truncated else ""
    click.echo(f"wrote {dst}: {done.written} ROS 2 messages on {done.topics} topics{cut}", err=True)


def _register_groups() -> None:
    from plumeswarm.cli.bench import bench
    from plumeswarm.cli.certs import certs
    from plumeswarm.cli.chaos import chaos

    cli.add_command(chaos)
    from plumeswarm.cli.plume import plume

    cli.add_command(plume)
    cli.add_command(certs)
    cli.add_command(bench)


_register_groups()


def main() -> None:
    try:
        cli(prog_name="plumeswarm")
    except PlumeswarmError as exc:  # any error of ours a command let through: its one line
        fail(" ".join(str(exc).split()) or type(exc).__name__)
    except ModuleNotFoundError as exc:  # an optional extra's module: one line naming the extra
        message = missing_extra_message(exc.name or "")
        if message is None:
            raise
        fail(message)


if __name__ == "__main__":
    main()
