"""A driver for a realtime flight that a test watches from another network namespace.

``python -m tests.support.rt_flight ROUTER VEHICLES ALTITUDE_M READY OUT``: joins the bus at
ROUTER, arms every vehicle of VEHICLES (comma-separated) and takes it off to ALTITUDE_M, touches
READY once every vehicle holds there, then appends every vehicle's latest state and status to
OUT (JSON lines, 20 per second) until SIGTERM. A vehicle's ``crashed`` is sticky in the
physics, so its last line tells.
"""

from __future__ import annotations

import json
import signal
import sys
import threading
import time
from pathlib import Path

from agents import Swarm
from swarmbus.messages import FlightMode

POLL_S = 0.05


def take_off(swarm: Swarm, vehicles: list[str], altitude_m: float, deadline: float) -> None:
    for vid in vehicles:
        commander = swarm.command(vid)
        while True:  # the autopilot may still be waiting for its first state
            try:
                commander.arm()
                commander.takeoff(altitude_m)
                break
            except Exception as exc:
                print(f"{vid}: {exc}", flush=True)
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)

    def holding(vid: str) -> bool:
        s, st = swarm.state(vid), swarm.status(vid)
        return (
            s is not None
            and st is not None
            and s.position_enu_m[2] > altitude_m - 0.5
            and st.mode == FlightMode.HOLD
        )

    swarm.wait_until(
        lambda: all(holding(v) for v in vehicles),
        timeout_s=max(1.0, deadline - time.monotonic()),
        what="every vehicle holding",
    )


def record(swarm: Swarm, vehicles: list[str], out: Path, stop: threading.Event) -> None:
    with out.open("a") as f:
        while not stop.wait(POLL_S):
            for vid in vehicles:
                s, st = swarm.state(vid), swarm.status(vid)
                if s is None or st is None:
                    continue
                line = {
                    "wall": time.monotonic(),
                    "id": vid,
                    "tick": s.tick,
                    "t": s.sim_time_s,
                    "z": s.position_enu_m[2],
                    "v": s.velocity_enu_m_s,
                    "crashed": s.crashed,
                    "on_ground": s.on_ground,
                    "motors": s.motors_enabled,
                    "mode": str(st.mode),
                    "armed": st.armed,
                    "failsafe": st.failsafe,
                }
                f.write(json.dumps(line) + "\n")
            f.flush()


def main() -> int:
    router, vids, altitude = sys.argv[1], sys.argv[2], float(sys.argv[3])
    ready, out = Path(sys.argv[4]), sys.argv[5]
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with Swarm.connect(connect=[router], command_timeout_s=5.0) as swarm:
        deadline = time.monotonic() + 120.0
        vehicles = sorted(vids.split(","))
        swarm.wait_until(lambda: set(swarm.autopilots_alive()) >= set(vehicles), timeout_s=60.0)
        take_off(swarm, vehicles, altitude, deadline)
        ready.write_text(",".join(vehicles))
        record(swarm, vehicles, Path(out), stop)
    return 0


if __name__ == "__main__":
    sys.exit(main())
