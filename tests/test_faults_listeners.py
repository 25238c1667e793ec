"""Every listener of the stack binds loopback by default: ``plumeswarm up`` (with the viewer)
is started with the bundled scenario's defaults and every LISTEN TCP socket and every bound
UDP socket of its processes is checked with psutil."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import psutil

from swarmbus.session import free_tcp_port
from tests.procs import REPO, wait_until

LOOPBACK = {"127.0.0.1", "::1"}


def start_up(args: list[str], out: Path) -> subprocess.Popen[bytes]:
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    with open(out / "console.txt", "wb") as console:
        return subprocess.Popen(
            [sys.executable, "-m", "deploy", "up", "--out", str(out / "run"), *args],
            cwd=REPO,
            env=env,
            stdout=console,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )


def listeners(procs: list[psutil.Process]) -> list[tuple[str, str, str, int]]:
    """(process, kind, ip, port) of every listening TCP / bound UDP socket."""
    found = []
    for p in procs:
        try:
            name = " ".join(p.cmdline()[3:6])
            conns = p.net_connections(kind="inet")
        except psutil.NoSuchProcess:
            continue
        for c in conns:
            if c.type == 1 and c.status == psutil.CONN_LISTEN:  # SOCK_STREAM
                found.append((name, "tcp", c.laddr.ip, c.laddr.port))
            elif c.type == 2 and c.laddr and not c.raddr:  # SOCK_DGRAM, not connected
                found.append((name, "udp", c.laddr.ip, c.laddr.port))
    return found


def test_every_listener_of_up_is_on_loopback(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    up = start_up(["--connect", endpoint], tmp_path)
    console = tmp_path / "console.txt"
    try:
        wait_until(
            lambda: "processes ready" in console.read_text() or up.poll() is not None,
            180.0,
            "plumeswarm up ready",
            poll_s=0.5,
        )
        assert up.poll() is None, console.read_text()
        family = [psutil.Process(up.pid), *psutil.Process(up.pid).children(recursive=True)]
        roles = {" ".join(p.cmdline()[3:5]) for p in family}
        found = listeners(family)
        assert found, f"no listener at all in {roles}"
        kinds = {k for _, k, _, _ in found}
        assert "udp" in kinds, f"no gateway UDP socket: {found}"
        exposed = [f for f in found if f[2] not in LOOPBACK]
        assert exposed == [], f"listening beyond loopback: {exposed}"
    finally:
        if up.poll() is None:
            os.kill(up.pid, signal.SIGTERM)
            try:
                up.wait(timeout=40)
            except subprocess.TimeoutExpired:
                os.killpg(up.pid, signal.SIGKILL)
                up.wait(10)
