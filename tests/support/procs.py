"""Helpers for tests that start real processes on a real Zenoh network on loopback.

Every process is started in its own process group and stopped by the test (``NodeProcs``);
every wait has a deadline and fails with a message saying what did not arrive.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Literal, TypeVar

import zenoh

from swarmbus.keys import Keys
from swarmbus.reqrep import NoReply, request
from swarmbus.session import NetworkConfig, free_tcp_port, open_session

REPO = Path(__file__).resolve().parents[2]
T = TypeVar("T")


def wait_until(
    predicate: Callable[[], T | Literal[False] | None],
    timeout_s: float,
    what: str,
    poll_s: float = 0.02,
) -> T:
    """Poll ``predicate`` until it returns something truthy; fail naming ``what`` otherwise."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:.1f} s waiting for {what}")
        time.sleep(poll_s)


def wait_for_queryable(
    session: zenoh.Session,
    key: str,
    message: object,
    reply_type: type[T],
    timeout_s: float,
    what: str,
) -> T:
    """Ask ``key`` (through ``swarmbus.reqrep``) until it replies, and return the reply (a
    node's queryable reaches a new peer shortly after its liveliness token does); fail naming
    ``what`` at the deadline. A refusal or a reply of another type raises at once."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return request(session, key, message, reply_type, 2.0)
        except NoReply:
            pass
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:.1f} s waiting for {what}")
        time.sleep(0.05)


class Network:
    """A router on a free loopback port and the config clients use to reach it."""

    def __init__(self, port: int) -> None:
        self.port = port
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.client = NetworkConfig(connect=[self.endpoint], listen=["tcp/127.0.0.1:0"])
        self.router = NetworkConfig(mode="router", connect=[], listen=[self.endpoint])

    def cli_args(self) -> list[str]:
        return ["--connect", self.endpoint, "--listen", "tcp/127.0.0.1:0"]


@contextmanager
def zenoh_network() -> Iterator[tuple[Network, zenoh.Session]]:
    """A router session in this test process (so the network outlives any child)."""
    net = Network(free_tcp_port())
    with open_session(net.router) as router:
        yield net, router


class NodeProcs:
    """Starts ``plumeswarm node ROLE`` processes; ``stop_all`` (or the context exit) ends them."""

    def __init__(
        self, net: Network, scenario: str | Path | None = None, log_dir: Path | None = None
    ):
        self.net = net
        self.scenario = str(scenario) if scenario is not None else None
        self.log_dir = log_dir
        self.procs: list[tuple[str, subprocess.Popen[bytes]]] = []

    def start(
        self,
        role: str,
        *args: str,
        name: str | None = None,
        env: Mapping[str, str] | None = None,
    ) -> subprocess.Popen[bytes]:
        cmd = ["plumeswarm", "node", role, *self.net.cli_args()]
        if self.scenario is not None:
            cmd += ["--scenario", self.scenario]
        label = name or "-".join([role, *[a for a in args if not a.startswith("-")]])
        return self.start_module(*cmd, *args, label=label, env=env)

    def start_module(
        self,
        module: str,
        *args: str,
        label: str,
        env: Mapping[str, str] | None = None,
        prefix: Sequence[str] = (),
    ) -> subprocess.Popen[bytes]:
        """``python -m MODULE ARGS`` in its own process group (``env`` added to this process's
        environment), its output in ``<label>.log`` of the log directory (if any); stopped
        with the others. ``prefix``: what runs it (``ip netns exec NAME``: in a namespace)."""
        out: int | IO[bytes] = subprocess.DEVNULL
        if self.log_dir is not None:
            out = open(self.log_dir / f"{label}.log", "wb")  # noqa: SIM115 - closed with the proc
        environ = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1", **(env or {}))
        proc = subprocess.Popen(
            [*prefix, sys.executable, "-m", module, *args],
            cwd=REPO,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=environ,
            start_new_session=True,
        )
        if not isinstance(out, int):
            out.close()  # the child holds its own descriptor
        self.procs.append((label, proc))
        return proc

    def kill(self, proc: subprocess.Popen[bytes], sig: int = signal.SIGKILL) -> None:
        with suppress(ProcessLookupError):
            os.killpg(proc.pid, sig)
        proc.wait(timeout=10)

    def stop_all(self, timeout_s: float = 10.0) -> None:
        for _, proc in self.procs:
            if proc.poll() is None:
                with suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + timeout_s
        for _, proc in self.procs:
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                with suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(timeout=5)

    def __enter__(self) -> NodeProcs:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()


@contextmanager
def repeating(period_s: float, action: Callable[[], None]) -> Iterator[None]:
    """``action()`` every ``period_s`` on a thread of its own until the block ends."""
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(period_s):
            action()

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join(5)


def keys_for(world: str = "default") -> Keys:
    return Keys(world)


# Our packages (docs/architecture.md, "Layers"): the process packages (roles) and the core the
# distribution installs.
PROCESS_PACKAGES = ["sim_world", "agents", "plume_service", "gcs_bridge", "recorder", "ros2_bridge"]
CORE_PACKAGES = ["swarmbus", "plume_atmosphere", *PROCESS_PACKAGES, "deploy"]
# How the launcher starts a node (the user layer's CLI); LaunchOptions.node_command.
NODE_COMMAND: tuple[str, ...] = (sys.executable, "-m", "plumeswarm")


def run_python(
    code: str, timeout_s: float = 120.0, env: Mapping[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """``python -c CODE`` in a fresh interpreter on this tree (bounded; ``env`` added to this
    process's environment); its output as text."""
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO), **(env or {})),
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )


def run_cli(
    args: Sequence[str], timeout_s: float = 120.0, env: Mapping[str, str] | None = None
) -> subprocess.CompletedProcess[str]:
    """Run ``python -m plumeswarm ARGS`` to completion (bounded; ``env`` added to this
    process's environment)."""
    environ = dict(os.environ, PYTHONPATH=str(REPO), **(env or {}))
    return subprocess.run(
        [sys.executable, "-m", "plumeswarm", *args],
        cwd=REPO,
        env=environ,
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
