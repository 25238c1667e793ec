"""Encode/decode cost of bus messages (the per-vehicle-state figure).

Run: ``python -m bench.codec``. Prints a table; no assertions.
"""

from __future__ import annotations

import argparse
import time

from swarmbus import messages as m
from swarmbus.codec import decode, encode
from tests.support.messages_samples import SAMPLES


def per_call_us(fn: object, n: int) -> float:
    call = fn  # type: ignore[assignment]
    best = float("inf")
    for _ in range(5):
        t0 = time.perf_counter()
        for _ in range(n):
            call()  # type: ignore[operator]
        best = min(best, (time.perf_counter() - t0) / n)
    return best * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("-n", type=int, default=20000, help="calls per timing round")
    args = parser.parse_args()
    state = SAMPLES[m.VehicleState]
    tick64 = m.SimTick(tick=1, sim_time_s=0.1, control_dt_s=1 / 120, states=[state] * 64)
    rows = [
        ("VehicleState", state, m.VehicleState),
        ("ActuatorCommand (4 rotors)", SAMPLES[m.ActuatorCommand], m.ActuatorCommand),
        ("SimTick, 64 vehicle states", tick64, m.SimTick),
        ("PlumeQuery, 2 points", SAMPLES[m.PlumeQuery], m.PlumeQuery),
    ]
    print(f"{'message':32} {'bytes':>7} {'encode µs':>10} {'decode µs':>10}")
    for name, msg, cls in rows:
        data = encode(msg)
        n = max(200, args.n // max(1, len(data) // 200))
        enc = per_call_us(lambda msg=msg: encode(msg), n)
        dec = per_call_us(lambda data=data, cls=cls: decode(data, cls), n)
        print(f"{name:32} {len(data):7d} {enc:10.2f} {dec:10.2f}")


if __name__ == "__main__":
    main()
