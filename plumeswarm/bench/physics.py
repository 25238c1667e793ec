"""Benchmark of the physics process: ticks/s and real-time factor against lockstep participants.

``python -m plumeswarm.bench.physics`` prints one markdown table: for N vehicles (default 1, 8, 32,
64,
128), grounded (zero throttle, resting on the ground: contacts every step) and hovering
(open-loop hover throttle at 20 m: no contacts), the ticks/s and real-time factor of
``plumeswarm node physics`` in lockstep mode at 240 Hz physics / 120 Hz control, answered by
lockstep participants (``plumeswarm/bench/lockstep_participant.py``; a few processes each serving
many
vehicles, answering inside the subscriber callback), plus the physics process's CPU share and
CPU milliseconds per tick (which, unlike ticks/s, barely depends on what else the machine
runs). A first table times the pure :class:`~sim_world.world.World` (no bus): control ticks
(2 substeps + reading all states) per wall second and per CPU second.

Rows run a few seconds each (``--seconds``); ``--long`` runs 20 s per row.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import suppress
from pathlib import Path

import psutil

from sim_world.world import World
from swarmbus.codec import decode
from swarmbus.keys import Keys
from swarmbus.messages import Clock
from swarmbus.scenario import parse_scenario
from swarmbus.session import NetworkConfig, free_tcp_port, open_session

REPO = Path(__file__).resolve().parent.parent
WORLD = "bench-physics"
SIZES = (1, 8, 32, 64, 128)


def scenario_toml(n: int, altitude_m: float) -> str:
    """N Iris quadcopters on a 3 m grid at ``altitude_m``."""
    side = max(1, int(n**0.5 + 0.999))
    lines = [
        f'[world]\nname = "{WORLD}"\n',
        "[time]\nphysics_hz = 240\ncontrol_hz = 120\nparticipant_timeout_s = 5.0\n"
        "startup_timeout_s = 120.0\n",
    ]
    for i in range(n):
        x, y = 3.0 * (i % side), 3.0 * (i // side)
        lines.append(f'[[vehicles]]\nid = "v{i}"\nspawn_enu_m = [{x}, {y}, {altitude_m}]\n')
    return "\n".join(lines)


def participant_groups(n: int) -> list[list[str]]:
    """Vehicle ids split over 1 (N = 1), 2 (N ≤ 8) or 4 processes."""
    procs = 1 if n == 1 else (2 if n <= 8 else 4)
    ids = [f"v{i}" for i in range(n)]
    return [ids[p::procs] for p in range(procs)]


class ClockWatch:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.samples: list[tuple[float, Clock]] = []

    def on_clock(self, sample: object) -> None:
        msg = decode(sample.payload.to_bytes(), Clock)  # type: ignore[attr-defined]
        with self.lock:
            self.samples.append((time.monotonic(), msg))

    def first(self) -> tuple[float, Clock] | None:
        with self.lock:
            started = [s for s in self.samples if s[1].tick > 0]
            return started[0] if started else None

    def last(self) -> tuple[float, Clock]:
        with self.lock:
            return self.samples[-1]


def _spawn(cmd: list[str], log: Path) -> subprocess.Popen[bytes]:
    env = dict(os.environ, PYTHONPATH=str(REPO))
    with open(log, "wb") as out:
        return subprocess.Popen(
            cmd, cwd=REPO, env=env, stdout=out, stderr=subprocess.STDOUT, start_new_session=True
        )


def _stop(procs: list[subprocess.Popen[bytes]]) -> None:
    for p in procs:
        if p.poll() is None:
            with suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGTERM)
    for p in procs:
        try:
            p.wait(timeout=10)
        except subprocess.TimeoutExpired:
            with suppress(ProcessLookupError):
                os.killpg(p.pid, signal.SIGKILL)
            p.wait(timeout=5)


def process_row(n: int, hovering: bool, seconds: float, tmp: Path) -> dict[str, float]:
    sc = tmp / f"n{n}-{'hover' if hovering else 'ground'}.toml"
    sc.write_text(scenario_toml(n, 20.0 if hovering else 0.0))
    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = NetworkConfig(mode="router", connect=[], listen=[endpoint])
    keys = Keys(WORLD)
    watch = ClockWatch()
    procs: list[subprocess.Popen[bytes]] = []
    with open_session(router) as session:
        sub = session.declare_subscriber(keys.clock(), watch.on_clock)
        try:
            net_args = ["--connect", endpoint, "--listen", "tcp/127.0.0.1:0"]
            physics = _spawn(
                [
                    sys.executable,
                    "-m",
                    "plumeswarm",
                    "node",
                    "physics",
                    "--scenario",
                    str(sc),
                    *net_args,
                ],
                tmp / f"physics-{sc.stem}.log",
            )
            procs.append(physics)
            throttle = [] if hovering else ["--throttle", "0.0"]
            for i, group in enumerate(participant_groups(n)):
                vehicles = [arg for vid in group for arg in ("--vehicle", vid)]
                procs.append(
                    _spawn(
                        [
                            *(sys.executable, "-m", "plumeswarm.bench.lockstep_participant"),
                            *("--connect", endpoint, "--scenario", str(sc), *vehicles, *throttle),
                        ],
                        tmp / f"script{i}-{sc.stem}.log",
                    )
                )
            deadline = time.monotonic() + 120.0
            while watch.first() is None:
                if time.monotonic() > deadline or physics.poll() is not None:
                    raise RuntimeError(f"physics did not start ticking; see {tmp}")
                time.sleep(0.05)
            first = watch.first()
            assert first is not None
            cpu0 = psutil.Process(physics.pid).cpu_times()
            time.sleep(seconds)
            cpu1 = psutil.Process(physics.pid).cpu_times()
            last = watch.last()
        finally:
            _stop(procs)
            sub.undeclare()
    wall = last[0] - first[0]
    ticks = last[1].tick - first[1].tick
    sim = last[1].sim_time_s - first[1].sim_time_s
    cpu = (cpu1.user + cpu1.system) - (cpu0.user + cpu0.system)
    return {
        "cpu_ms_tick": 1000.0 * cpu / max(1, ticks),
        "ticks_s": ticks / wall,
        "rtf": sim / wall,
        "cpu": cpu / seconds,
        "participants": float(len(participant_groups(n))),
    }


def world_row(n: int, hovering: bool, seconds: float) -> tuple[float, float]:
    """Control ticks (2 substeps + states) per wall second and per CPU second, bare World."""
    sc = parse_scenario(scenario_toml(n, 20.0 if hovering else 0.0))
    with World(sc) as world:
        vt = world.vehicle_type("v0")
        u = 0.0
        if hovering:
            g = 9.81
            w = (vt.mass_kg * g / (len(vt.rotors) * vt.thrust_coeff_n_per_rad2_s2)) ** 0.5
            u = w / vt.max_rotor_speed_rad_s
        for vid in world.vehicle_ids:
            world.apply(vid, [u] * len(vt.rotors))
        ticks = 0
        start = time.perf_counter()
        cpu_start = time.process_time()
        while time.perf_counter() - start < seconds:
            for _ in range(10):
                world.step(2)
                world.states(ticks)
                ticks += 1
        elapsed = time.perf_counter() - start
        cpu = time.process_time() - cpu_start
    return ticks / elapsed, ticks / cpu


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--seconds", type=float, default=3.0, help="measuring time per row")
    p.add_argument("--long", action="store_true", help="20 s per row")
    p.add_argument("--sizes", default=",".join(map(str, SIZES)), help="vehicle counts")
    p.add_argument("--no-bus", action="store_true", help="only the pure World table")
    args = p.parse_args(argv)
    seconds = 20.0 if args.long else args.seconds
    sizes = [int(s) for s in args.sizes.split(",") if s]
    print(f"# physics bench: 240 Hz physics / 120 Hz control, lockstep, {os.cpu_count()} cores\n")
    print("## pure World (no bus): control ticks (2 steps + states) per second\n")
    print("Per CPU second is what one free core gives; per wall second depends on the load.\n")
    print("| N | state | ticks/wall s | ticks/CPU s | real-time factor (CPU) |")
    print("|---:|---|---:|---:|---:|")
    for n in sizes:
        for hovering in (False, True):
            wall_rate, cpu_rate = world_row(n, hovering, min(seconds, 2.0))
            state = "hovering" if hovering else "grounded"
            print(
                f"| {n} | {state} | {wall_rate:,.0f} | {cpu_rate:,.0f} | {cpu_rate / 120:.1f}x |",
                flush=True,
            )
    if args.no_bus:
        return 0
    print("\n## physics process over Zenoh with lockstep participants\n")
    print(
        "| N | state | participant procs | ticks/s | real-time factor | physics CPU "
        "| physics CPU ms/tick |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory(prefix="bench-physics-") as tmp:
        for n in sizes:
            for hovering in (False, True):
                r = process_row(n, hovering, seconds, Path(tmp))
                state = "hovering" if hovering else "grounded"
                print(
                    f"| {n} | {state} | {r['participants']:.0f} | {r['ticks_s']:,.0f} | "
                    f"{r['rtf']:.1f}x | {100 * r['cpu']:.0f} % | {r['cpu_ms_tick']:.2f} |",
                    flush=True,
                )
    return 0


if __name__ == "__main__":
    sys.exit(main())
