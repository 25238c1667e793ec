"""Recorder benchmarks: messages/s the recorder sustains here, and file size per vehicle-minute.

Run with ``python -m plumeswarm.bench.recorder``. Three measurements:

1. the writer alone (decode MessagePack → JSON → MCAP chunk, zstd): the cost per message
   without Zenoh;
2. end to end: a publisher process sends VehicleStates as fast as it can to a real recorder
   process through a router; the rate is counted from the first message to the recorder's
   acknowledgement that it recorded the last one (so nothing is still queued);
3. paced: N vehicles × 120 Hz VehicleState in real time for a few seconds — does the recorder
   keep up, and at what CPU share of one core.

File size per vehicle-minute is that of a 120 Hz VehicleState stream (7200 messages).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import psutil

from recorder.handshake import wait_until_recorded
from recorder.reader import Recording
from recorder.sink import McapSink
from recorder.spool import Spool
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import NodeState, VehicleState
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario
from swarmbus.session import NetworkConfig, Presence, free_tcp_port, open_session

REPO = Path(__file__).resolve().parent.parent
STATE_HZ = 120


def state(vehicle: int, tick: int) -> VehicleState:
    """A plausible, changing state (so compression sees realistic data, not repeats)."""
    t = tick / STATE_HZ
    a = 0.3 * t + vehicle
    return VehicleState(
        vehicle_id=f"uav{vehicle + 1}",
        tick=tick,
        sim_time_s=t,
        position_enu_m=(30 + 12 * math.cos(a), 12 * math.sin(a), 10 + 0.1 * math.sin(3 * t)),
        velocity_enu_m_s=(-3.6 * math.sin(a), 3.6 * math.cos(a), 0.3 * math.cos(3 * t)),
        attitude_xyzw=(0.01 * math.sin(t), 0.01 * math.cos(t), math.sin(a / 2), math.cos(a / 2)),
        body_rates_rad_s=(0.02 * math.sin(5 * t), 0.02 * math.cos(5 * t), 0.3),
        lat_deg=47.397742 + 1e-6 * math.sin(a),
        lon_deg=8.545594 + 1e-6 * math.cos(a),
        alt_m=498.0 + 0.1 * math.sin(3 * t),
        on_ground=False,
    )


def stream(vehicles: int, ticks: int) -> list[tuple[str, bytes]]:
    return [
        (Keys("default").vehicle_state(f"uav{v + 1}"), encode(state(v, k)))
        for k in range(ticks)
        for v in range(vehicles)
    ]


def writer_alone(messages: int = 120_000, vehicles: int = 8) -> tuple[float, float]:
    """(messages/s, bytes per vehicle-minute) of McapSink alone."""
    data = stream(vehicles, messages // vehicles)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "w.mcap"
        sink = McapSink(path)
        t0 = time.perf_counter()
        base = time.time_ns()
        for i, (key, payload) in enumerate(data):
            sink.write_bus(key, payload, base + i * 1_000_000_000 // (STATE_HZ * vehicles))
            if i % 1000 == 0:
                sink.maybe_close_chunk()
        sink.close()
        elapsed = time.perf_counter() - t0
        size = path.stat().st_size
    vehicle_minutes = len(data) / (STATE_HZ * 60)
    return len(data) / elapsed, size / vehicle_minutes


# ----------------------------------------------------------------------------- bus benches
def publish(args: argparse.Namespace) -> int:
    """Child process: publish VehicleStates (burst or paced), hand-shaken with the recorder."""
    net = NetworkConfig(connect=[args.connect], listen=["tcp/127.0.0.1:0"])
    ctx = NodeContext(load_scenario(DEFAULT_SCENARIO), net, "bench-pub")
    data = stream(args.vehicles, args.ticks)
    with NodeRuntime(ctx, role="bench") as rt:
        pubs = {k: rt.session.declare_publisher(k) for k, _ in data[: args.vehicles]}
        up = NodeState.UP
        wait_until_recorded(rt.session, rt.keys, "bench-pub", up, lambda: rt.publish_health(up))
        t0 = time.perf_counter()
        if args.paced:
            for k in range(args.ticks):
                due = t0 + k / STATE_HZ
                delay = due - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                for key, payload in data[k * args.vehicles : (k + 1) * args.vehicles]:
                    pubs[key].put(payload)
        else:
            for key, payload in data:
                pubs[key].put(payload)
        t_sent = time.perf_counter()
        stop = NodeState.STOPPING
        wait_until_recorded(
            rt.session, rt.keys, "bench-pub", stop, lambda: rt.publish_health(stop), timeout_s=120
        )
        t_ack = time.perf_counter()
    print(json.dumps({"sent_s": t_sent - t0, "recorded_s": t_ack - t0, "count": len(data)}))
    return 0


def spool_alone(messages: int = 120_000, vehicles: int = 8) -> float:
    """Microseconds per message appended to the write-ahead spool (recorder.spool)."""
    items = stream(vehicles, max(1, messages // vehicles))
    with tempfile.TemporaryDirectory() as tmp:
        spool = Spool(Path(tmp) / "s.mcap")
        t0 = time.perf_counter()
        for k, (key, payload) in enumerate(items):
            spool.append((key, payload, k, k, False))
        dt = time.perf_counter() - t0
        spool.close(remove=True)
    return 1e6 * dt / len(items)


def through_bus(vehicles: int, ticks: int, paced: bool, spool: bool = True) -> dict[str, Any]:
    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router = NetworkConfig(mode="router", connect=[], listen=[endpoint])
    env = dict(os.environ, PYTHONPATH=str(REPO))
    with tempfile.TemporaryDirectory() as tmp, open_session(router):
        out = Path(tmp) / "bus.mcap"
        rec = subprocess.Popen(
            [sys.executable, "-m", "plumeswarm", "node", "recorder", "--connect", endpoint,
             "--set", f"out={out}", "--set", "query_plume_info=false",
             "--set", f"spool={str(spool).lower()}"],
            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip
        try:
            proc = psutil.Process(rec.pid)
            with open_session(NetworkConfig(connect=[endpoint])) as session:
                presence = Presence(session, Keys())
                if not presence.wait_for(lambda alive: "recorder" in alive, 60.0):
                    raise RuntimeError("the recorder did not come up")
                presence.close()
            cmd = [
                sys.executable,
                "-m",
                "plumeswarm.bench.recorder",
                "--publish",
                "--connect",
                endpoint,
            ]
            cmd += ["--vehicles", str(vehicles), "--ticks", str(ticks)]
            cmd += ["--paced"] if paced else []
            cpu0 = sum(proc.cpu_times()[:2])
            res = subprocess.run(
                cmd, cwd=REPO, env=env, capture_output=True, text=True, timeout=300
            )
            cpu1 = sum(proc.cpu_times()[:2])
            if res.returncode != 0:
                raise RuntimeError(f"publisher failed: {res.stderr[-2000:]}")
            result = json.loads(res.stdout.strip().splitlines()[-1])
        finally:
            os.killpg(rec.pid, signal.SIGTERM)
            rec.wait(60)
        recording = Recording.open(out)
        topics = [(m.topic, m.event()) for m in recording.messages()]
        behind = sum(1 for _, e in topics if e is not None and e.kind == "behind")
        recorded = sum(1 for t, _ in topics if t.endswith("/state"))
        summary = recording.metadata.get("plumeswarm.summary", {})
    return {
        "count": result["count"],
        "sent_s": result["sent_s"],
        "recorded_s": result["recorded_s"],
        "cpu_s": cpu1 - cpu0,
        "dropped": float(summary.get("dropped_total", "nan")),
        "behind": behind,
        "recorded": recorded,
        "gaps": sum(json.loads(summary.get("tick_gaps", "{}")).values()),
        "truncated": recording.truncated,
        "summary": summary,
    }


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--publish", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--connect", default="")
    p.add_argument("--vehicles", type=int, default=8)
    p.add_argument("--ticks", type=int, default=1000)
    p.add_argument("--paced", action="store_true")
    p.add_argument("--quick", action="store_true", help="shorter runs")
    p.add_argument("--steps", type=int, nargs="*", default=[8, 64, 128, 256, 512])
    p.add_argument(
        "--spool",
        action="store_true",
        help="only the write-ahead spool's cost: alone, and the "
        "recorder's CPU with and without it (--steps vehicles, paced)",
    )
    args = p.parse_args()
    if args.publish:
        sys.exit(publish(args))
    if args.spool:
        spool_cost(args)
        return

    scale = 0.25 if args.quick else 1.0
    rate, per_vm = writer_alone(int(120_000 * scale))
    print("| measurement | value |")
    print("|---|---|")
    print(f"| writer alone (transcode + MCAP + zstd), 8 vehicles | {rate:,.0f} msg/s |")
    print(f"| file size, 120 Hz VehicleState | {per_vm / 1e6:.2f} MB per vehicle-minute |")
    print()
    print(
        "| offered (vehicles × 120 Hz VehicleState) | recorded / sent | lost, seen as tick gaps "
        "| recorder CPU | behind events |"
    )
    print("|---|---|---|---|---|")
    seconds = 3.0 * scale
    for vehicles in args.steps:
        r = through_bus(vehicles, int(STATE_HZ * seconds), paced=True)
        offered = vehicles * STATE_HZ
        cpu = 100 * r["cpu_s"] / r["sent_s"]
        print(
            f"| {vehicles} × {STATE_HZ} Hz = {offered:,} msg/s for {r['sent_s']:.1f} s | "
            f"{r['recorded']:,} / {r['count']:,} (recorder dropped {r['dropped']:.0f}) | "
            f"{r['count'] - r['recorded']:,}, {r['gaps']:,} | {cpu:.0f} % of a core | "
            f"{r['behind']} |",
            flush=True,
        )


def spool_cost(args: argparse.Namespace) -> None:
    scale = 0.25 if args.quick else 1.0
    print(f"spool alone: {spool_alone(int(120_000 * scale)):.2f} µs per message appended")
    print("| offered | spool | recorded / sent | recorder CPU |")
    print("|---|---|---|---|")
    for vehicles in args.steps:
        for spool in (False, True, False, True):
            r = through_bus(vehicles, int(STATE_HZ * 3.0 * scale), paced=True, spool=spool)
            cpu = 100 * r["cpu_s"] / r["sent_s"]
            print(
                f"| {vehicles} × {STATE_HZ} Hz | {'on' if spool else 'off'} | "
                f"{r['recorded']:,} / {r['count']:,} | {cpu:.0f} % of a core |",
                flush=True,
            )


if __name__ == "__main__":
    main()
