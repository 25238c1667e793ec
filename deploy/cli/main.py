"""The ``plumeswarm`` command line. Argument parsing lives only in :mod:`deploy.cli` (click)."""

from __future__ import annotations

import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click

from deploy.cli.common import (
    SET_OPT,
    connect_option,
    fail,
    scenario_file,
    scenario_from,
    vehicles_per_process_option,
)
from deploy.roles import BENCH_ROLES, ROLES, RoleUnavailable, role_entry
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
    """Validate FILE (or a bundled scenario's NAME); print a one-line summary, or one line
    naming the bad field."""
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
    """The bundled scenarios (or DIR's), one a line: name, vehicles, plume, first comment line."""
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
@cli.command()
@click.argument("role", type=click.Choice([*sorted(ROLES), *sorted(BENCH_ROLES)]))
@SCENARIO_OPT
@click.option("--vehicle", "vehicles", multiple=True, help="Vehicle id(s) this node serves.")
@click.option("--name", default=None, help="Node name on the bus (default: derived from role).")
@connect_option
@click.option("--listen", multiple=True, help="Zenoh endpoint to listen on (repeatable).")
@click.option("--mode", type=click.Choice(["peer", "client", "router"]), default=None)
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
    """Run one ROLE alone (for deployments across machines)."""
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
    try:
        entry = role_entry(role)
    except RoleUnavailable as exc:
        fail(str(exc))
    ctx = NodeContext(sc, net, node_name, tuple(vehicles), opts)
    sys.exit(entry(ctx))


# ---------------------------------------------------------------------------- the rest
@cli.command()
@click.argument("scenario_arg", metavar="[SCENARIO]", required=False)
@SCENARIO_OPT
@click.option("--headless", is_flag=True, help="No viewer.")
@click.option("--record", is_flag=True, help="Also run the recorder (MCAP in the run directory).")
@click.option(
    "--foxglove",
    "foxglove_live",
    is_flag=True,
    help="Also serve the run live to Foxglove (WebSocket on 127.0.0.1).",
)
@click.option(
    "--foxglove-port",
    type=click.IntRange(0, 65535),
    default=None,
    help="Port of the live Foxglove server (implies --foxglove; default 8765, 0: any free).",
)
@click.option(
    "--ros2",
    "ros2_bridge",
    is_flag=True,
    help="Also run the ROS 2 bridge: the run as ROS 2 topics for rmw_zenoh (docs/ros2.md).",
)
@click.option(
    "--ros2-domain",
    type=click.IntRange(0, 232),
    default=None,
    help="ROS domain id of the bridge (implies --ros2; default: ROS_DOMAIN_ID, else 0).",
)
@click.option("--out", type=click.Path(path_type=Path), default=None, help="Run directory.")
@click.option("--connect", multiple=True, help="Router endpoint (default: the scenario's).")
@click.option("--listen", multiple=True, help="Endpoint every node listens on.")
@click.option("--roles", default=None, help="Only these roles, comma-separated (one host of many).")
@click.option("--no-router", is_flag=True, help="Do not start a router (another host runs it).")
@click.option("--hosts", "hosts_file", type=click.Path(path_type=Path), default=None)
@click.option("--host", "host_name", default=None, help="This host's entry in --hosts.")
@vehicles_per_process_option("Vehicles each autopilot process serves.")
@click.option(
    "--stepped",
    is_flag=True,
    help="Stepped clock: the world advances only when one client steps it (Swarm.step).",
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
    scenario_overrides: tuple[str, ...],
) -> None:
    """Start the whole swarm (plume, physics, autopilots, gateway, viewer) and supervise it."""
    from deploy.console import Console
    from deploy.hosts import HostsError, load_deployment, options_for_host
    from deploy.launcher import LaunchError, LaunchOptions, default_run_dir
    from deploy.security import secure_launch
    from deploy.up import run_up
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
        scenario_path=path,
        headless=headless,
        record=record,
        run_dir=run_dir,
        connect=connect,
        listen=listen,
        roles=_names(roles) if roles else None,
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
        sys.exit(run_up(sc, opts, Console()))
    except LaunchError as exc:
        fail(str(exc), code=1)


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
@click.option("--timeout", "timeout_s", type=float, default=900.0, show_default=True)
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
    from experiments.demo import DemoOptions, run_demo

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
    sys.exit(run_demo(opts, Console()))


@cli.command()
@SCENARIO_OPT
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@click.option("--connect", multiple=True, help="Router endpoint (default: the scenario's).")
@click.option("--timeout", "timeout_s", type=float, default=5.0, show_default=True)
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
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path), default=None)
def record(scenario: str | None, connect: tuple[str, ...], out: Path | None) -> None:
    """Record everything on the bus to an MCAP file (until Ctrl-C)."""
    from deploy.cli import recording as commands

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
    from deploy.cli import recording as commands

    sc = scenario_from(scenario)
    sys.exit(commands.replay(file, sc, list(connect), speed, wait_for, recorded_by))


@cli.command()
@click.argument("file")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path))
def report(file: str, out: Path) -> None:
    """Plots, CSV and a one-page report from a recording."""
    from deploy.cli import recording as commands

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
    from recorder.foxglove.export import ExportError
    from recorder.foxglove.export import export_foxglove as run_export
    from recorder.foxglove.layout import layout_json
    from recorder.reader import RecordingError

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
    from deploy.ros2_export import ExportError
    from deploy.ros2_export import export_ros2 as run_export
    from recorder.reader import RecordingError

    try:
        done = run_export(src, dst)
    except (RecordingError, ExportError) as exc:
        fail(str(exc))
    cut = " (IN was cut short: read to its last complete chunk)" if done.truncated else ""
    click.echo(f"wrote {dst}: {done.written} ROS 2 messages on {done.topics} topics{cut}", err=True)


@cli.group()
def bench() -> None:
    """Benchmarks of the full stack."""


def _names(value: str) -> tuple[str, ...]:
    """A comma-separated list's items."""
    return tuple(v.strip() for v in value.split(",") if v.strip())


def _bench_dir(out: Path | None, bench_name: str) -> Path:
    """``out``, or ``runs/bench-<name>-<local time>/``."""
    import time

    return out or Path("runs") / time.strftime(f"bench-{bench_name}-%Y%m%d-%H%M%S")


def _exit_by_rows(rows: list[dict[str, object]]) -> None:
    """Exit status 1 when a row holds an error, else 0."""
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
@click.option("--vehicles", default="1,2,4,8,16,32,64", callback=_int_list, show_default=True)
@vehicles_per_process_option()
@click.option("--state", "states", default="grounded,hovering,flying", show_default=True)
@click.option("--seconds", type=click.FloatRange(min=0.5), default=8.0, show_default=True)
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
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=None)
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
    from bench.scale import ScaleError, ScaleOptions, run_scale

    opts = ScaleOptions(
        scenario=scenario_from(scenario, scenario_overrides),
        out=_bench_dir(out, "scale"),
        vehicles=vehicles,
        states=_names(states),
        seconds=seconds,
        vehicles_per_process=vehicles_per_process,
        gateway=not no_gateway,
        sensor_period_ticks=sensor_period_ticks,
        baseline=baseline,
        ros2=ros2,
    )
    try:
        rows = run_scale(opts, click.echo)
    except ScaleError as exc:
        fail(str(exc))
    _exit_by_rows(rows)


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
    help="Comma-separated: fused (one process, no bus), bus (the distributed stack).",
)
@click.option(
    "--steps", type=click.IntRange(min=1), default=30, show_default=True, help="Timed steps."
)
@click.option(
    "--ticks-per-step", type=click.IntRange(min=1), default=12, show_default=True,
    help="Control ticks per environment step.",
)  # fmt: skip
@vehicles_per_process_option("Bus backend: autopilot processes serve this many vehicles each.")
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Directory for envs.json (default: runs/bench-envs-<time>/).",
)
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
    from bench.envs import EnvBenchOptions, run_env_bench

    opts = EnvBenchOptions(
        scenario=sc,
        out=_bench_dir(out, "envs"),
        vehicles=vehicles,
        backends=_names(backends),
        steps=steps,
        ticks_per_step=ticks_per_step,
        vehicles_per_process=vehicles_per_process,
    )
    try:
        rows = run_env_bench(opts, click.echo)
    except ValueError as exc:
        fail(str(exc))
    _exit_by_rows(rows)


def _gsl_options(seed_default: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """The options ``bench gsl`` and ``bench gsl sweep`` share."""
    options = [
        click.option(
            "--algorithms",
            default="all",
            show_default=True,
            help="Comma-separated names, name=module:Class, or 'all'; random_walk and oracle "
            "always run.",
        ),
        click.option(
            "--environments",
            default="all",
            show_default=True,
            help="Comma-separated names (deploy/scenarios/gsl) or scenario paths, or 'all'.",
        ),
        click.option(
            "--sensors",
            default="all",
            show_default=True,
            help="Comma-separated, or 'all' available.",
        ),
        click.option("--runs", type=click.IntRange(min=1), default=30, show_default=True),
        click.option(
            "--seed",
            type=click.IntRange(min=0, max=2**31 - 1),
            default=seed_default,
            show_default=True,
            help="Published tables: 0; tuning: >= 1000.",
        ),
        click.option(
            "--time-limit",
            "time_limit_s",
            type=click.FloatRange(min=1.0),
            default=300.0,
            show_default=True,
            help="Seconds of simulated time per run.",
        ),
        click.option(
            "--dynamics",
            type=click.Choice(["kinematic", "full"]),
            default="kinematic",
            show_default=True,
            help="kinematic: point masses following the setpoint; full: pybullet vehicles and "
            "autopilots.",
        ),
        click.option(
            "--control-hz",
            type=click.IntRange(min=1, max=1000),
            default=20,
            show_default=True,
            help="Behaviour rate with kinematic dynamics (full uses the scenario's).",
        ),
        click.option(
            "--sensor-period-ticks",
            type=click.IntRange(min=1),
            default=2,
            show_default=True,
            help="A reading every N control ticks (kinematic; full: 10 Hz).",
        ),
        click.option(
            "--jobs",
            type=click.IntRange(min=1),
            default=2,
            show_default=True,
            help="Worker processes.",
        ),
        click.option(
            "--out",
            type=click.Path(file_okay=False, path_type=Path),
            default=None,
            help="Output directory (default runs/bench-gsl-…).",
        ),
    ]

    def apply(f: Callable[..., None]) -> Callable[..., None]:
        for option in reversed(options):
            f = option(f)
        return f

    return apply


def _gsl_run(
    kwargs: dict[str, Any],
    run: Callable[[Any, Path, Any], list[Path]],
    check: Callable[[Any], None] | None = None,
) -> None:
    """Validate the options, run with a progress bar, write, and say what was written."""
    import time

    from tqdm import tqdm

    from experiments.gsl_bench import GslError, availability_lines, make_options

    out = kwargs.pop("out")
    jobs = kwargs["jobs"]
    try:
        opts = make_options(
            _names(kwargs.pop("algorithms")),
            _names(kwargs.pop("environments")),
            _names(kwargs.pop("sensors")),
            **kwargs,
        )
        if check is not None:
            check(opts)
    except GslError as exc:
        fail(str(exc))
    for line in availability_lines():
        click.echo(line)
    started = time.monotonic()
    with tqdm(total=1, desc="episodes", unit="run", file=sys.stderr) as bar:

        def progress(done: int, total: int) -> None:
            bar.total = total
            bar.update(done - bar.n)

        directory = _bench_dir(out, "gsl")
        try:
            written = run(opts, directory, progress)
        except GslError as exc:
            fail(str(exc))
    click.echo(written[0].read_text())
    click.echo(f"wall time {time.monotonic() - started:.0f} s on {jobs} worker process(es)")
    for path in written:
        click.echo(f"wrote {path}")


@bench.group("gsl", invoke_without_command=True)
@_gsl_options(seed_default=0)
@click.pass_context
def bench_gsl(ctx: click.Context, /, **kwargs: Any) -> None:
    """Source seeking: algorithms × environments × sensors, N seeded runs per cell."""
    if ctx.invoked_subcommand is not None:
        return
    from experiments.gsl_bench import rows_of, run_all, write_outputs

    def run(opts: Any, directory: Path, progress: Any) -> list[Path]:
        outcomes = run_all(opts, progress)
        return write_outputs(directory, opts, rows_of(opts, outcomes), outcomes)

    _gsl_run(kwargs, run)


@bench_gsl.command("sweep")
@click.argument("params", nargs=-1, required=True)
@click.option(
    "--allow-test-seeds",
    is_flag=True,
    help="Sweep seeds < 1000 anyway (the output then says so).",
)
@_gsl_options(seed_default=1000)
def bench_gsl_sweep(params: tuple[str, ...], allow_test_seeds: bool, **kwargs: Any) -> None:
    """One table per PARAM=v1,v2,… (behavior.NAME, start.along_m or a scenario section.key)."""
    from experiments.gsl_bench import GslError
    from experiments.gsl_sweep import (
        parse_sweep,
        run_sweep,
        seed_warning,
        value_specs,
        write_sweep,
    )

    try:
        parsed = [parse_sweep(p) for p in params]
    except GslError as exc:
        fail(str(exc))

    def check(opts: Any) -> None:
        warning = seed_warning(opts, allow_test_seeds)
        if warning:
            click.echo(warning, err=True)
        for param in parsed:  # every value valid before any episode flies
            for value in param.values:
                value_specs(opts, param.name, value)

    def run(opts: Any, directory: Path, progress: Any) -> list[Path]:
        tables = run_sweep(opts, parsed, progress)
        return write_sweep(directory, opts, parsed, tables, seed_warning(opts, allow_test_seeds))

    _gsl_run(kwargs, run, check)


@bench.command("pomdp")
@click.option("--dims", type=int, default=2, show_default=True, help="Space dimensions: 1, 2 or 3.")
@click.option("--lambda-over-dx", type=float, default=2.0, show_default=True, help="λ/Δx, >= 1.")
@click.option("--r-dt", type=float, default=2.0, show_default=True, help="R·Δt, > 0.")
@click.option("--episodes", type=int, default=1000, show_default=True)
@click.option("--seed", type=int, default=0, show_default=True)
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    default=None,
    help="Directory for pomdp.json (default runs/bench-pomdp-<time>/).",
)
def bench_pomdp(
    dims: int,
    lambda_over_dx: float,
    r_dt: float,
    episodes: int,
    seed: int,
    out: Path | None,
) -> None:
    """Infotaxis on the source-tracking POMDP (Loisy & Eloy 2022), evaluated as OTTO does."""
    import time

    from bench.pomdp import PomdpError, PomdpOptions, report_lines, run_pomdp, write_result

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
    directory = out or Path("runs") / time.strftime("bench-pomdp-%Y%m%d-%H%M%S")
    click.echo(f"wrote {write_result(directory, result)}")


def _register_groups() -> None:
    from deploy.cli.certs import certs
    from deploy.cli.chaos import chaos

    cli.add_command(chaos)
    from deploy.cli.plume import plume

    cli.add_command(plume)
    cli.add_command(certs)


_register_groups()


def main() -> None:
    try:
        cli(prog_name="plumeswarm")
    except ModuleNotFoundError as exc:  # an optional extra's module: one line naming the extra
        message = missing_extra_message(exc.name or "")
        if message is None:
            raise
        fail(message)


if __name__ == "__main__":
    main()
