"""Encode/decode cost of bus messages (the per-vehicle-state figure).

Run: ``python -m plumeswarm.bench.codec``. Prints a table; no assertions.
"""

from __future__ import annotations

import argparse
import time

from swarmbus import messages as m
from swarmbus.codec import decode, encode

# One vehicle's state as the physics publishes it, a quadrotor's command, a two-point query.
STATE = m.VehicleState(
    vehicle_id="uav1",
    tick=42,
    sim_time_s=0.35,
    position_enu_m=(20.0, -4.0, 10.0),
    velocity_enu_m_s=(1.0, 0.0, -0.1),
    attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
    body_rates_rad_s=(0.01, -0.02, 0.0),
    lat_deg=47.397742,
    lon_deg=8.545859,
    alt_m=498.0,
    on_ground=False,
)
COMMAND = m.ActuatorCommand(vehicle_id="uav1", tick=42, rotor_commands=[0.5, 0.5, 0.5, 0.5])
QUERY = m.PlumeQuery(points_enu_m=[(20.0, 0.0, 10.0), (30.0, 1.0, 9.0)], sim_time_s=2.0)


def per_call_us(fn: object, n: int) -> float:
    call = fn
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
    state = STATE
    tick64 = m.SimTick(tick=1, sim_time_s=0.1, control_dt_s=1 / 120, states=[state] * 64)
    rows = [
        ("VehicleState", state, m.VehicleState),
        ("ActuatorCommand (4 rotors)", COMMAND, m.ActuatorCommand),
        ("SimTick, 64 vehicle states", tick64, m.SimTick),
        ("PlumeQuery, 2 points", QUERY, m.PlumeQuery),
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
