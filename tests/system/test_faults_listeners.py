"""Every listener of the stack binds loopback by default: ``plumeswarm up`` (with the viewer, the
live Foxglove server and the ROS 2 bridge) is started with the bundled scenario's defaults and
every LISTEN TCP socket and every bound UDP socket of its processes is checked with psutil."""

from __future__ import annotations

from pathlib import Path

import psutil

from swarmbus.session import free_tcp_port
from tests.support.procs import wait_until
from tests.support.upstack import plumeswarm_up

LOOPBACK = {"127.0.0.1", "::1"}


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
    fox_port = free_tcp_port()
    with plumeswarm_up(None, tmp_path, "--foxglove-port", str(fox_port), "--ros2") as up:
        family = [
            psutil.Process(up.proc.pid),
            *psutil.Process(up.proc.pid).children(recursive=True),
        ]
        roles = {" ".join(p.cmdline()[3:5]) for p in family}
        found = wait_until(
            lambda: (f := listeners(family)) and any(port == fox_port for *_, port in f) and f,
            30.0,
            f"the live Foxglove server listening on {fox_port} among {roles}",
        )
        kinds = {k for _, k, _, _ in found}
        assert "udp" in kinds, f"no gateway UDP socket: {found}"
        exposed = [f for f in found if f[2] not in LOOPBACK]
        assert exposed == [], f"listening beyond loopback: {exposed}"
