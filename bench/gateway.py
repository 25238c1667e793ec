"""Gateway telemetry benchmark: rates per simulated second and the gateway's CPU, N vehicles.

Run with ``python -m bench.gateway [N ...] [--backend real]``. Each row starts a router, the
scripted fake autopilot (kinematic vehicles at ``--speed`` × real time; it stands in for physics +
autopilots, which would dominate the machine long before the gateway does) or, with
``--backend real``, plume + physics + one autopilot per vehicle, and the gateway,
then listens on the GCS port like QGC and measures, over 8 s of sim time, the lowest rate of the
fast streams (telemetry_hz, default 4 Hz) and of the 1 Hz streams across all vehicles, in
messages per simulated second, plus the heartbeat rate per wall second and the gateway's CPU.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

import psutil

from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, heard_all, measure_rates, write_scenario
from tests.support.procs import zenoh_network

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


def row(n: int, speed: float, tmp: Path, backend: str) -> str:
    scenario, gcs_port, _ = write_scenario(tmp / f"bench{n}.toml", n)
    ids = [f"uav{i + 1}" for i in range(n)]
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp, ids, backend=backend, speed=speed),
        gateway(net, scenario, tmp) as gw,
        MavClient(gcs_port) as c,
    ):
        seen: set[int] = set()
        c.wait(
            "every sysid",
            partial(heard_all, seen, n),
            120.0,
        )
        proc = psutil.Process(gw.pid)
        c.drain()  # count only what arrives from now on
        cpu0 = proc.cpu_times()
        beats0 = len([m for m in c.log if m.get_type() == "HEARTBEAT"])
        t0 = time.monotonic()
        rates, wall = measure_rates(c, sorted(seen), sim_seconds=8.0, timeout_s=300.0)
        cpu1 = proc.cpu_times()
        elapsed = time.monotonic() - t0
        beats = len([m for m in c.log if m.get_type() == "HEARTBEAT"]) - beats0
    cpu = (cpu1.user + cpu1.system - cpu0.user - cpu0.system) / elapsed * 100.0
    fast = min(r.get(k, 0.0) for r in rates.values() for k in FAST)
    slow = min(r.get(k, 0.0) for r in rates.values() for k in ONE_HZ)
    return (
        f"{n:>8} {8.0 / wall:>9.2f}x {fast:>12.2f} {slow:>12.2f} "
        f"{beats / elapsed / n:>12.2f} {cpu:>10.0f}%"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("vehicles", nargs="*", type=int, default=[1, 4, 16, 32])
    ap.add_argument("--speed", type=float, default=2.0, help="fake sim speed (× real time)")
    ap.add_argument(
        "--backend",
        choices=["fake", "real"],
        default="fake",
        help="real: plume + physics (lockstep, as fast as it goes) + autopilots",
    )
    args = ap.parse_args()
    print(
        f"{'vehicles':>8} {'sim speed':>10} {'fast min/s':>12} {'1 Hz min/s':>12} "
        f"{'hb/s (wall)':>12} {'gw CPU':>11}",
        flush=True,
    )
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.vehicles:
            print(row(n, args.speed, Path(tmp), args.backend), flush=True)
    print(
        "rates: messages per simulated second (configured: fast 4, slow 1); "
        f"sim speed: as achieved by the {args.backend} stack",
        file=sys.stderr,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
