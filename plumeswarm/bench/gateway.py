"""Gateway telemetry benchmark: rates per simulated second and the gateway's CPU, N vehicles.

Run with ``python -m plumeswarm.bench.gateway [N ...] [--speed S] [--per-process K]``. Each row
starts the
real stack through the launcher (router, plume, physics in realtime mode at S × the wall clock,
default 2, one autopilot process per K vehicles, default 8, and the gateway), listens on the
GCS port like QGC, and measures, over 8 s of sim time, the lowest rate of the fast streams
(telemetry_hz, default 4 Hz) and of the 1 Hz streams across all vehicles, in messages per
simulated second, plus the heartbeat rate per wall second and the gateway's CPU. The vehicles
stay on the ground (the gateway's work does not depend on where they fly).
"""

from __future__ import annotations

import argparse
import collections
import select
import socket
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgspec
import psutil

from deploy.launcher import Launcher, LaunchOptions
from deploy.scaling import write_scenario
from gcs_bridge.dialect import new_mav
from plumeswarm.bench.scale import prepare
from plumeswarm.experiments.launch import NODE_COMMAND
from swarmbus.scenario import Scenario, load_scenario, resolve_scenario_path
from swarmbus.session import free_udp_block

FAST = (
    "SYS_STATUS",
    "GPS_RAW_INT",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "VFR_HUD",
    "EXTENDED_SYS_STATE",
    "NAMED_VALUE_FLOAT",
)
ONE_HZ = ("BATTERY_STATUS", "MISSION_CURRENT")
SIM_SECONDS = 8.0
ROLES = ("router", "plume", "physics", "autopilot", "gateway")


def scenario(n: int, speed: float, tmp: Path) -> tuple[Scenario, Path, int]:
    """novak2018 with ``n`` vehicles, in realtime at ``speed`` × the wall clock, on free router
    and MAVLink ports."""
    sc, _ = prepare(load_scenario(resolve_scenario_path(None)), n, tmp)
    time_ = msgspec.structs.replace(sc.time, mode="realtime", speed_factor=speed)
    gcs = free_udp_block(1)
    gw = msgspec.structs.replace(
        sc.gateway, host="127.0.0.1", gcs_port=gcs, api_port_base=free_udp_block(n)
    )
    sc = msgspec.structs.replace(sc, gateway=gw, time=time_)
    return sc, write_scenario(sc, tmp / "scenario.toml"), gcs


class Listener:
    """The GCS side, as QGC listens (``udpin``): every MAVLink message the gateway sends."""

    def __init__(self, port: int) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)

    def receive(self, timeout_s: float = 0.05) -> list[Any]:
        select.select([self.sock], [], [], timeout_s)
        out: list[Any] = []
        while True:
            try:
                data = self.sock.recv(65535)
            except BlockingIOError:
                return out
            out += [m for m in new_mav(0, 0).parse_buffer(data) or [] if m.get_type() != "BAD_DATA"]


class Window:
    """Per vehicle: the messages between its first ATTITUDE and the one ``SIM_SECONDS`` of sim
    time (ATTITUDE's time_boot_ms) later."""

    def __init__(self, sysids: set[int]) -> None:
        self.first: dict[int, int] = {}
        self.last: dict[int, int] = {}
        self.counts = {s: collections.Counter[str]() for s in sysids}

    def full(self, s: int) -> bool:
        return s in self.last and self.last[s] - self.first[s] >= SIM_SECONDS * 1000

    def take(self, m: Any) -> None:
        s = m.get_srcSystem()
        if s not in self.counts or self.full(s):
            return
        if m.get_type() == "ATTITUDE":
            self.first.setdefault(s, m.time_boot_ms)
            self.last[s] = m.time_boot_ms
        if s in self.first:
            self.counts[s][m.get_type()] += 1

    def done(self) -> bool:
        return all(self.full(s) for s in self.counts)

    def lowest(self, kinds: tuple[str, ...]) -> float:
        """The lowest rate, per simulated second, of ``kinds`` across the vehicles."""
        return min(
            c[k] / ((self.last[s] - self.first[s]) / 1000.0)
            for s, c in self.counts.items()
            for k in kinds
        )


def heard(listen: Listener, n: int, timeout_s: float) -> set[int]:
    """The sysids of ``n`` vehicles, once each one's HEARTBEAT has arrived."""
    seen: set[int] = set()
    deadline = time.monotonic() + timeout_s
    while len(seen) < n:
        if time.monotonic() > deadline:
            raise RuntimeError(f"heard {len(seen)} of {n} vehicles in {timeout_s:.0f} s")
        seen.update(m.get_srcSystem() for m in listen.receive() if m.get_type() == "HEARTBEAT")
    return seen


def measure(listen: Listener, sysids: set[int], timeout_s: float) -> tuple[Window, int, float]:
    """The window, the heartbeats heard meanwhile and its wall seconds."""
    window = Window(sysids)
    beats = 0
    t0 = time.monotonic()
    while not window.done():
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError(f"sim time did not advance {SIM_SECONDS} s in {timeout_s:.0f} s")
        for m in listen.receive():
            beats += m.get_type() == "HEARTBEAT"
            window.take(m)
    return window, beats, time.monotonic() - t0


def row(n: int, speed: float, per_process: int, tmp: Path) -> str:
    sc, path, gcs_port = scenario(n, speed, tmp)
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        run_dir=tmp,
        roles=ROLES,
        vehicles_per_process=per_process,
        verbose=0,
    )
    listen = Listener(gcs_port)
    try:
        with Launcher(sc, opts) as launcher:
            launcher.close_view()  # the launcher's own view of every state: not needed
            sysids = heard(listen, n, 120.0)
            gw = psutil.Process(launcher.supervisor.pids()["gateway"])
            listen.receive(0.0)  # count only what arrives from now on
            cpu0 = gw.cpu_times()
            window, beats, wall = measure(listen, sysids, 300.0)
            cpu1 = gw.cpu_times()
    finally:
        listen.sock.close()
    cpu = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / wall * 100.0
    return (
        f"{n:>8} {SIM_SECONDS / wall:>9.2f}x {window.lowest(FAST):>12.2f} "
        f"{window.lowest(ONE_HZ):>12.2f} {beats / wall / n:>12.2f} {cpu:>10.0f}%"
    )


def main() -> int:
    ap = argparse.ArgumentParser(prog="python -m plumeswarm.bench.gateway", description=__doc__)
    ap.add_argument("vehicles", nargs="*", type=int, default=[1, 4, 16, 32])
    ap.add_argument("--speed", type=float, default=2.0, help="sim time per wall second")
    ap.add_argument("--per-process", type=int, default=8, help="vehicles per autopilot process")
    args = ap.parse_args()
    print(
        f"{'vehicles':>8} {'sim speed':>10} {'fast min/s':>12} {'1 Hz min/s':>12} "
        f"{'hb/s (wall)':>12} {'gw CPU':>11}",
        flush=True,
    )
    for n in args.vehicles:
        with tempfile.TemporaryDirectory() as tmp:
            print(row(n, args.speed, args.per_process, Path(tmp)), flush=True)
    print(
        "rates: messages per simulated second (configured: fast 4, slow 1); "
        "sim speed: as achieved by the stack",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
