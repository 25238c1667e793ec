"""``plumeswarm up``: start the roles of one run as OS processes, see them ready, supervise, stop.

The plan (which processes, with which command lines and policies) is pure data built from the
scenario and the options (:func:`plan`); :class:`Launcher` carries it out with a
:class:`~deploy.supervisor.Supervisor`, learns readiness from liveliness tokens
(:class:`~swarmbus.session.Presence`) and never from sleeps, and writes ``pids.json`` into the run
directory.

Physics saves its world to ``physics.ckpt`` in the run directory; after a crash the supervisor
restarts it (on-failure) and it resumes from that checkpoint. A new run removes a checkpoint
left in the directory by an earlier one, so it starts from the spawn.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import msgspec
import zenoh

from agents.resume import checkpoint_paths
from deploy.busview import BusView, status_line
from deploy.roles import ROLES
from deploy.supervisor import (
    ExitEvent,
    ProcessSpec,
    ProcState,
    RestartMode,
    RestartPolicy,
    Supervisor,
)
from sim_world import checkpoint
from swarmbus.closeable import Closeable
from swarmbus.codec import encode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys, process_node
from swarmbus.messages import NodeState, RestartNotice
from swarmbus.scenario import Scenario
from swarmbus.session import DEFAULT_ROUTER, NetworkConfig, open_session

log = logging.getLogger(__name__)

ALL_ROLES = (
    "router",
    "recorder",
    "plume",
    "physics",
    "autopilot",
    "gateway",
    "viewer",
    "foxglove",
    "ros2",
)
# Stop order: the world and its edges first (so no autopilot is "dropped" from a lockstep that
# is still running), then the autopilots and the plume, then the recorder, the router last.
STOP_STAGE = {
    "gateway": 0,
    "viewer": 0,
    "foxglove": 0,
    "ros2": 0,
    "physics": 0,
    "autopilot": 1,
    "plume": 1,
    "recorder": 2,
    "router": 3,
}
RESTART = {
    # on the same endpoints: every session reconnects to it (swarmbus.session.CONNECT_RETRY)
    "router": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),
    "physics": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),  # from its checkpoint
    "recorder": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),  # in a new segment
    "plume": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),
    "autopilot": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),
    "gateway": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),
    "viewer": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=2),
    "foxglove": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=2),
    "ros2": RestartPolicy(RestartMode.ON_FAILURE, max_restarts=3),
}
NOT_CRITICAL = {"viewer", "foxglove", "ros2"}


class LaunchError(PlumeswarmError, RuntimeError):
    """The run could not start: one line saying why."""


@dataclass(frozen=True)
class LaunchOptions:
    scenario_path: Path
    headless: bool = False
    record: bool = False
    foxglove: bool = False  # also the live Foxglove WebSocket server (role ``foxglove``)
    ros2: bool = False  # also the ROS 2 bridge (role ``ros2``)
    run_dir: Path = Path("runs")
    connect: tuple[str, ...] = ()  # the router endpoint(s); default: the scenario's
    listen: tuple[str, ...] = ()  # what each node listens on; default: loopback, any port
    roles: tuple[str, ...] | None = None  # only these roles (one host of many); None: all
    router: bool = True  # start the router here
    vehicles: tuple[str, ...] | None = None  # autopilots for these vehicles; None: all
    vehicles_per_process: int = 1  # autopilot processes serve this many vehicles each
    verbose: int = 1
    # The command that runs ``node ROLE …`` (the user layer's CLI, e.g. ``python -m plumeswarm``):
    # handed down by whoever launches, since orchestration never names the layer above it.
    node_command: tuple[str, ...] = ()
    node_options: dict[str, tuple[str, ...]] = field(default_factory=dict)  # role → KEY=VALUE
    node_args: tuple[str, ...] = ()  # for every node (e.g. --hosts/--host: its TLS identity)
    client_network: NetworkConfig | None = None  # the launcher's own session (e.g. with TLS)
    # role → the ``node`` role that runs in its place, under the same process name (the bench's
    # ceiling stand-ins, deploy.ceiling); default: each role runs itself
    stand_ins: dict[str, str] = field(default_factory=dict)


def router_endpoints(scenario: Scenario, opts: LaunchOptions) -> list[str]:
    return list(opts.connect) or list(scenario.network.connect) or [DEFAULT_ROUTER]


def selected_roles(opts: LaunchOptions) -> list[str]:
    roles = list(opts.roles) if opts.roles is not None else list(ALL_ROLES)
    unknown = [r for r in roles if r not in ROLES]
    if unknown:
        raise LaunchError(f"unknown role(s) {', '.join(unknown)}; roles: {', '.join(ROLES)}")
    if opts.headless and "viewer" in roles and opts.roles is None:
        roles.remove("viewer")
    if not opts.record and "recorder" in roles and opts.roles is None:
        roles.remove("recorder")
    if not opts.foxglove and "foxglove" in roles and opts.roles is None:
        roles.remove("foxglove")
    if not opts.ros2 and "ros2" in roles and opts.roles is None:
        roles.remove("ros2")
    if not opts.router and "router" in roles:
        roles.remove("router")
    return [r for r in ALL_ROLES if r in roles]


def missing_roles(roles: Sequence[str]) -> list[str]:
    """Roles whose entry module is not installed (a broken or partial installation)."""
    missing = []
    for role in roles:
        module = ROLES[role].partition(":")[0]
        try:
            found = importlib.util.find_spec(module) is not None
        except ModuleNotFoundError:
            found = False
        if not found:
            missing.append(role)
    return missing


def plan(scenario: Scenario, opts: LaunchOptions) -> list[ProcessSpec]:
    """The processes of this run, in start order."""
    endpoints = router_endpoints(scenario, opts)
    listen = list(opts.listen) or ["tcp/127.0.0.1:0"]
    if not opts.node_command:
        raise LaunchError("LaunchOptions.node_command is empty: the command that runs `node ROLE`")
    base = [*opts.node_command] + ["-v"] * opts.verbose
    common = ["--scenario", str(opts.scenario_path)]
    vehicle_ids = (
        list(opts.vehicles) if opts.vehicles is not None else [v.id for v in scenario.vehicles]
    )
    specs: list[ProcessSpec] = []

    def add(role: str, name: str, extra: Sequence[str]) -> None:
        entry = opts.stand_ins.get(role, role)
        named = ["--name", name] if entry != role else []
        args = [*base, "node", entry, *common, *named, *extra, *opts.node_args]
        for item in opts.node_options.get(role, ()):
            args += ["--set", item]
        specs.append(
            ProcessSpec(
                name=name,
                role=role,
                argv=tuple(args),
                restart=RESTART[role],
                stop_stage=STOP_STAGE[role],
                critical=role not in NOT_CRITICAL,
            )
        )

    net_args = [a for ep in endpoints for a in ("--connect", ep)] + [
        a for ep in listen for a in ("--listen", ep)
    ]
    for role in selected_roles(opts):
        if role == "router":
            add(role, "router", [a for ep in endpoints for a in ("--listen", ep)])
        elif role == "autopilot":
            k = max(1, opts.vehicles_per_process)
            for i in range(0, len(vehicle_ids), k):
                chunk = vehicle_ids[i : i + k]
                name = process_node("autopilot", chunk)
                state = f"checkpoint={autopilot_state_path(opts, name)}"  # agents.resume
                add(role, name, [a for vid in chunk for a in ("--vehicle", vid)] + net_args)
                specs[-1] = replace(specs[-1], argv=(*specs[-1].argv, "--set", state))
        else:
            add(role, role, [*net_args, *run_dir_options(role, opts)])
    return specs


def run_dir_options(role: str, opts: LaunchOptions) -> list[str]:
    """The ``--set`` options that put what a role keeps across its restarts in the run
    directory: the physics's checkpoint, the recording (a restarted recorder continues in the
    next segment, recording.1.mcap …), the gateway's signed streams' timestamps."""
    sets = {
        "physics": [f"checkpoint={checkpoint_path(opts)}"],
        "recorder": [f"out={opts.run_dir / 'recording.mcap'}", "resume=true"],
        "gateway": [f"signing_state={opts.run_dir / 'mavlink-signing.state'}"],
    }
    return [a for item in sets.get(role, []) for a in ("--set", item)]


def served_vehicles(spec: ProcessSpec) -> list[str]:
    """The vehicles an autopilot process serves (its ``--vehicle`` arguments)."""
    argv = spec.argv
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == "--vehicle"]


def checkpoint_path(opts: LaunchOptions) -> Path:
    return opts.run_dir / "physics.ckpt"


def autopilot_state_path(opts: LaunchOptions, node_name: str) -> Path:
    """Where an autopilot process keeps its checkpoints (``agents.resume``)."""
    return opts.run_dir / f"{node_name}.state"


def default_run_dir(root: Path = Path("runs")) -> Path:
    return root / time.strftime("%Y%m%d-%H%M%S")


def _last_lines(path: Path, n: int = 3) -> str:
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return " / ".join(ln.strip() for ln in lines[-n:] if not ln.startswith("--- start"))


class Launcher(Closeable):
    """Carries out a plan: ``with Launcher(sc, opts) as l: l.supervise(stop)``."""

    def __init__(
        self,
        scenario: Scenario,
        opts: LaunchOptions,
        console: Callable[[str], None] | None = None,
    ) -> None:
        self.scenario = scenario
        self.opts = opts
        self.keys = Keys(scenario.world.name)
        self.run_dir = opts.run_dir
        self.specs = plan(scenario, opts)
        self.console = console
        self.supervisor = Supervisor(self.specs, self.run_dir, console=console)
        self._session: zenoh.Session | None = None
        self.view: BusView | None = None
        self._errors: dict[str, str] = {}  # processes whose health says error: the detail
        self.started_at = time.monotonic()

    # ------------------------------------------------------------------ start
    def _client_network(self) -> NetworkConfig:
        # The launcher's own session: a peer that only connects to the router.
        own = self.scenario.network  # its TLS identity, if the scenario has one
        base = self.opts.client_network or NetworkConfig(
            tls=own.tls, access_control=own.access_control
        )
        return msgspec.structs.replace(
            base, connect=router_endpoints(self.scenario, self.opts), listen=[]
        )

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("the launcher has no bus session before start()")
        return self._session

    def start(self, on_bus: Callable[[zenoh.Session], None] | None = None) -> None:
        """Start everything; ``on_bus(session)`` runs once the router is up and before any
        other role starts (subscribe there to see a run from its first message)."""
        roles = sorted({s.role for s in self.specs})
        missing = missing_roles(roles)
        if missing:
            raise LaunchError(
                "cannot start: role(s) not installed: "
                + ", ".join(f"{r} ({ROLES[r].partition(':')[0]})" for r in missing)
            )
        self.run_dir.mkdir(parents=True, exist_ok=True)
        if any(s.role == "physics" for s in self.specs):
            checkpoint.remove(checkpoint_path(self.opts))  # an earlier run's: start from spawn
        for spec in self.specs:
            if spec.role == "autopilot":  # likewise: autopilots start fresh
                for path in checkpoint_paths(autopilot_state_path(self.opts, spec.name)):
                    path.unlink(missing_ok=True)
        timeout = self.scenario.time.startup_timeout_s
        first = [s.name for s in self.specs if s.role == "router"]
        if first:
            self.supervisor.start_all(first)
        self._wait_router(timeout)
        self._session = open_session(self._client_network())
        self.view = BusView(self._session, self.keys)
        if first:
            self.wait_ready(first, timeout)
        if on_bus is not None:
            on_bus(self._session)
        # The recorder before anything publishes, the plume before the lockstep starts (the
        # first sensor ticks are answered); then everything else together.
        early = [s.name for s in self.specs if s.role in ("recorder", "plume")]
        if early:
            self.supervisor.start_all(early)
            self.wait_ready(early, timeout)
        rest = [s.name for s in self.specs if s.name not in first + early]
        self.supervisor.start_all(rest)
        self.wait_ready(rest, timeout)
        self.write_pids()

    def _wait_router(self, timeout_s: float) -> None:
        # The router (ours or another host's) must accept connections before anyone joins.
        import socket

        endpoints = router_endpoints(self.scenario, self.opts)
        deadline = time.monotonic() + timeout_s
        for ep in endpoints:
            proto, _, addr = ep.partition("/")
            if proto not in ("tcp", "tls"):  # a TLS listener accepts TCP connections first
                continue
            host, _, port = addr.rpartition(":")
            while True:
                self._check_exits()
                try:
                    with socket.create_connection((host.strip("[]"), int(port)), timeout=0.5):
                        break
                except OSError:
                    if time.monotonic() > deadline:
                        raise LaunchError(
                            f"router did not accept connections on {ep} within {timeout_s:.0f} s"
                        ) from None
                    time.sleep(0.05)

    def _check_exits(self) -> None:
        self.supervisor.poll()
        for sv in self.supervisor.failed_for_good():
            detail = _last_lines(sv.log_path)
            raise LaunchError(
                f"{sv.spec.name} exited with code {sv.returncode} before it was ready"
                + (f": {detail}" if detail else "")
                + f" (log: {sv.log_path})"
            )

    def wait_ready(self, names: Sequence[str], timeout_s: float) -> None:
        """Until every name has a liveliness token; fail fast when one of them exits."""
        assert self.view is not None
        wanted = set(names)
        deadline = time.monotonic() + timeout_s
        while True:
            self._check_exits()
            alive = self.view.presence.alive
            if wanted <= alive:
                return
            if time.monotonic() > deadline:
                missing = ", ".join(sorted(wanted - alive))
                raise LaunchError(f"not ready within {timeout_s:.0f} s: {missing}")
            self.view.presence.wait_for(lambda a: wanted <= a, 0.2)

    def write_pids(self) -> Path:
        path = self.run_dir / "pids.json"
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(self.supervisor.pids(), indent=2) + "\n")
        tmp.replace(path)
        return path

    # ------------------------------------------------------------------ run
    def status_line(self) -> str:
        if self.view is None:
            return ""
        expected = sum(1 for s in self.specs if s.role == "autopilot") or None
        return status_line(self.view.snapshot(), expected)

    def supervise_once(self) -> None:
        """Reap and restart; raise :class:`LaunchError` when a critical process is gone."""
        before = self.supervisor.pids()
        for event in self.supervisor.poll():
            self._announce(event)
            if event.restarting:
                log.warning(
                    "%s exited with code %d: restarting in %.1f s",
                    event.name,
                    event.returncode,
                    event.delay_s,
                )
            else:
                log.warning("%s exited with code %d", event.name, event.returncode)
        if self.supervisor.pids() != before:
            self.write_pids()
        self._watch_errors()
        failed = self.supervisor.failed_for_good()
        if failed:
            sv = failed[0]
            raise LaunchError(
                f"{sv.spec.name} exited with code {sv.returncode}: {_last_lines(sv.log_path)}"
            )

    def _watch_errors(self) -> None:
        """Log each of our processes that says on its health it is failing at its job (a
        recorder on a full disk), and when it recovers; restarting would not help."""
        if self.view is None:
            return
        health = self.view.snapshot().health
        for name, sv in self.supervisor.procs.items():
            h = health.get(name)
            failing = h is not None and h.state is NodeState.ERROR
            if failing and h is not None and name not in self._errors:
                log.error("%s reports an error: %s", name, h.detail)
                self._errors[name] = h.detail
            elif not failing and name in self._errors and sv.state is ProcState.RUNNING:
                del self._errors[name]
                log.warning("%s recovered: %s", name, h.detail if h is not None else "")

    def _announce(self, event: ExitEvent) -> None:
        """Say on the bus that a process ended and whether it is being restarted: the physics
        holds the lockstep for the vehicles of an autopilot being restarted."""
        if self._session is None:
            return
        sv = self.supervisor.procs[event.name]
        notice = RestartNotice(
            node=event.name,
            role=sv.spec.role,
            restarting=event.restarting,
            returncode=event.returncode,
            delay_s=event.delay_s,
            restarts=sv.restarts,
            vehicles=served_vehicles(sv.spec),
        )
        try:
            self._session.put(self.keys.node_restart(event.name), encode(notice))
        except zenoh.ZError as exc:
            log.warning("could not announce the restart of %s: %s", event.name, exc)

    def supervise(
        self,
        stop: threading.Event,
        on_status: Callable[[str], None] | None = None,
        status_period_s: float = 1.0,
    ) -> None:
        """Until ``stop`` is set (or a critical process is gone for good)."""
        next_status = 0.0
        while not stop.is_set():
            self.supervise_once()
            if not any(
                sv.state in (ProcState.RUNNING, ProcState.BACKOFF)
                for sv in self.supervisor.procs.values()
            ):
                return
            now = time.monotonic()
            if on_status is not None and now >= next_status:
                on_status(self.status_line())
                next_status = now + status_period_s
            stop.wait(0.1)

    # ------------------------------------------------------------------ stop
    def close_view(self) -> None:
        """Drop the launcher's view of the bus (presence, status); the stack runs on."""
        if self.view is not None:
            self.view.close()
            self.view = None

    def stop(self) -> dict[str, int | None]:
        # Our own session goes first: it must not outlive the router it talks through.
        self.close_view()
        if self._session is not None:
            self._session.close()
            self._session = None
        return self.supervisor.stop_all()

    def __enter__(self) -> Launcher:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def close(self) -> None:
        """:meth:`stop` (what leaving ``with`` does), without the exit codes."""
        self.stop()
