"""What the Foxglove channels cost the recorder's writer thread.

Run with ``python -m plumeswarm.bench.foxglove [--vehicles 32] [--seconds 20]``. A 32-vehicle run
at 120 Hz
control as the bus carries it (per tick one ``sim/tick`` with every state and one
``vehicle/<id>/state`` per vehicle; a ``vehicle/<id>/concentration`` per vehicle at 10 Hz) is
written through the recorder's sink (MessagePack → JSON → MCAP) with and without the Foxglove
conversion (:class:`recorder.foxglove.scene.FoxgloveScene`). Prints a table and writes JSON: sim
seconds written per wall second (the real-time factor the writer alone could keep up with), CPU
per sim second, file size.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path
from typing import Any

from plumeswarm.bench.recorder import STATE_HZ, state
from recorder.foxglove.channels import (
    TRAIL_MAX_POINTS,
    TRAILS_PERIOD_S,
)
from recorder.foxglove.channels import (
    encode as encode_message,
)
from recorder.foxglove.scene import (
    FoxgloveScene,
)
from recorder.sink import McapSink
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import ConcentrationReading, SimTick
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario

SENSOR_EVERY = 12  # 10 Hz at 120 Hz


def run_stream(vehicles: int, seconds: float) -> list[tuple[str, bytes]]:
    keys = Keys("default")
    out: list[tuple[str, bytes]] = []
    for k in range(round(seconds * STATE_HZ)):
        states = [state(v, k) for v in range(vehicles)]
        tick = SimTick(tick=k, sim_time_s=k / STATE_HZ, control_dt_s=1 / STATE_HZ, states=states)
        out.append((keys.tick(), encode(tick)))
        out += [(keys.vehicle_state(s.vehicle_id), encode(s)) for s in states]
        if k % SENSOR_EVERY == 0:
            for s in states:
                reading = ConcentrationReading(
                    vehicle_id=s.vehicle_id,
                    sim_time_s=s.sim_time_s,
                    position_enu_m=s.position_enu_m,
                    available=True,
                    reported_g_m3=0.05,
                    true_g_m3=0.05,
                )
                out.append((keys.vehicle_concentration(s.vehicle_id), encode(reading)))
    return out


def write(data: list[tuple[str, bytes]], seconds: float, foxglove: bool) -> dict[str, Any]:
    scenario = load_scenario(DEFAULT_SCENARIO)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "f.mcap"
        sink = McapSink(path)
        scene = FoxgloveScene(scenario) if foxglove else None
        base = time.time_ns()
        step = 1_000_000_000 * seconds / len(data)
        t0, c0 = time.perf_counter(), time.process_time()
        for i, (key, payload) in enumerate(data):
            log_ns = base + round(i * step)
            message = sink.write_bus(key, payload, log_ns)
            if scene is not None and message is not None:
                for out in scene.feed(message, log_ns):
                    sink.write_foxglove(out)
            if i % 1000 == 0:
                sink.maybe_close_chunk()
        sink.close()
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        size = path.stat().st_size
    return {
        "foxglove": foxglove,
        "messages": len(data),
        "sim_s_per_wall_s": seconds / wall,
        "cpu_s_per_sim_s": cpu / seconds,
        "mb_per_sim_minute": size / 1e6 * 60 / seconds,
    }


def full_trails(vehicles: int, repeats: int = 5) -> dict[str, float]:
    """The trail message once every trail is at its longest (the worst case of a long run)."""
    scene = FoxgloveScene(None)
    for k in range(TRAIL_MAX_POINTS + 1):
        states = [state(v, k * STATE_HZ) for v in range(vehicles)]
        scene.feed(SimTick(tick=k, sim_time_s=float(k), control_dt_s=1.0, states=states), 0)
    t0 = time.perf_counter()
    for _ in range(repeats):
        update = scene.trails_update(0)
        assert update is not None
        size = len(encode_message(update))
    return {"ms": (time.perf_counter() - t0) / repeats * 1e3, "bytes": size}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--vehicles", type=int, default=32)
    p.add_argument("--seconds", type=float, default=20.0)
    p.add_argument("--out", type=Path, default=Path("bench-foxglove.json"))
    args = p.parse_args()
    data = run_stream(args.vehicles, args.seconds)
    rows = [write(data, args.seconds, fox) for fox in (False, True)]
    print(f"{args.vehicles} vehicles, {STATE_HZ} Hz, {args.seconds:g} s sim, {len(data)} messages")
    print(f"{'foxglove':>9} {'sim s / wall s':>15} {'cpu s / sim s':>14} {'MB / sim min':>13}")
    for r in rows:
        print(
            f"{'on' if r['foxglove'] else 'off':>9} {r['sim_s_per_wall_s']:>15.2f} "
            f"{r['cpu_s_per_sim_s']:>14.3f} {r['mb_per_sim_minute']:>13.1f}"
        )
    trails = full_trails(args.vehicles)
    print(
        f"full trails ({args.vehicles} × {TRAIL_MAX_POINTS} points, every "
        f"{TRAILS_PERIOD_S:g} s of sim): {trails['ms']:.0f} ms to build and encode, "
        f"{trails['bytes'] / 1e6:.2f} MB"
    )
    result = {"vehicles": args.vehicles, "rows": rows, "full_trails": trails}
    args.out.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
