"""``plumeswarm up`` as a subprocess for fault tests: started on a free router port, ready when
it says "processes ready", stopped with SIGTERM (SIGKILL of its group after a deadline)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh

from deploy.busview import BusView
from deploy.launcher import LaunchOptions
from swarmbus.keys import Keys
from swarmbus.session import free_tcp_port
from tests.support.procs import NODE_COMMAND, REPO, wait_until


@dataclass
class Up:
    proc: subprocess.Popen[bytes]
    run: Path
    endpoint: str
    console: Path

    def pids(self) -> dict[str, int]:
        return dict(json.loads((self.run / "pids.json").read_text()))

    def restarted(self, name: str, old: int, timeout_s: float = 60.0) -> int:
        """The new pid of ``name`` once the supervisor has restarted it."""
        return int(
            wait_until(
                lambda: (p := self.pids().get(name)) not in (None, old) and p,
                timeout_s,
                f"{name} to be restarted",
                poll_s=0.05,
            )
        )

    def kill(self, name: str) -> tuple[int, float, int]:
        """SIGKILL ``name``'s process group: (new pid, wall seconds until the supervisor
        restarted it, kill time in ns since the epoch)."""
        old = self.pids()[name]
        t0, t0_ns = time.monotonic(), time.time_ns()
        os.killpg(old, signal.SIGKILL)
        new = self.restarted(name, old)
        return new, time.monotonic() - t0, t0_ns


@dataclass
class StackOnBus:
    """A stack started by ``plumeswarm up`` and the test's session on it; a test's own stack
    class adds what its callbacks collect (under ``lock``)."""

    up: Up
    session: zenoh.Session
    keys: Keys
    view: BusView
    gcs_port: int
    lock: threading.Lock = field(default_factory=threading.Lock)


def spawn_up(args: Sequence[str], out: Path) -> subprocess.Popen[bytes]:
    """``plumeswarm up ARGS --out OUT/run`` in its own process group; console in OUT/console.txt."""
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    with open(out / "console.txt", "wb") as console:
        return subprocess.Popen(
            [sys.executable, "-m", "plumeswarm", "up", "--out", str(out / "run"), *args],
            cwd=REPO, env=env, stdout=console, stderr=subprocess.STDOUT, start_new_session=True,
        )  # fmt: skip


def stop_up(proc: subprocess.Popen[bytes], timeout_s: float = 60.0) -> None:
    """SIGTERM (the launcher's ordered stop); SIGKILL of its group after ``timeout_s``."""
    if proc.poll() is not None:
        return
    os.kill(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)


@contextmanager
def plumeswarm_up(
    scenario: Path | None, tmp: Path, *args: str, ready_timeout_s: float = 180.0
) -> Iterator[Up]:
    """``plumeswarm up`` on a free router port (``scenario`` None: the bundled default), until
    it says "processes ready"; stopped on exit."""
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    console = tmp / "console.txt"
    scenario_args = [str(scenario)] if scenario is not None else []
    proc = spawn_up([*scenario_args, "--connect", endpoint, *args], tmp)
    try:
        wait_until(
            lambda: "processes ready" in console.read_text() or proc.poll() is not None,
            ready_timeout_s,
            "plumeswarm up ready",
            poll_s=0.5,
        )
        assert proc.poll() is None, console.read_text()[-3000:]
        yield Up(proc, tmp / "run", endpoint, console)
    finally:
        stop_up(proc)


def recording_launch(scenario: Path, run_dir: Path, endpoint: str, **kw: Any) -> LaunchOptions:
    """Launch options of a headless recorded stack without gateway (router, recorder, plume,
    physics, autopilots) on ``endpoint``; ``kw`` adds to them."""
    return LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=scenario,
        headless=True,
        record=True,
        run_dir=run_dir,
        connect=(endpoint,),
        roles=("router", "recorder", "plume", "physics", "autopilot"),
        **kw,
    )
