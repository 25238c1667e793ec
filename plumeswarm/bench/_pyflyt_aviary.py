"""Run inside PyFlyt's own virtualenv by ``plumeswarm/bench/pyflyt.py`` (it imports nothing of
plumeswarm).

``python _pyflyt_aviary.py N SECONDS``: N PyFlyt quadx drones on a 3 m grid in one
``Aviary`` (240 Hz physics, 120 Hz control: two physics steps per ``step()``), flying
position setpoints (mode 7) that jump 3 m sideways every 2 s of sim time, so the controllers
keep working. After 1 s of sim time it counts ``step()`` calls for SECONDS of wall time and
prints one JSON line: steps, wall seconds, CPU seconds of this process, steps per second,
real-time factor.
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np
from PyFlyt.core import Aviary

CONTROL_HZ = 120
PHYSICS_HZ = 240
ALTITUDE_M = 10.0


def main() -> None:
    n, seconds = int(sys.argv[1]), float(sys.argv[2])
    side = max(1, int(np.ceil(np.sqrt(n))))
    grid = np.array([[3.0 * (i % side), 3.0 * (i // side), 0.1] for i in range(n)])
    env = Aviary(
        start_pos=grid,
        start_orn=np.zeros((n, 3)),
        drone_type="quadx",
        drone_options={"control_hz": CONTROL_HZ},
        render=False,
        physics_hz=PHYSICS_HZ,
        seed=0,
    )
    env.set_mode(7)  # position setpoint: x, y, yaw, z

    def setpoints(step: int) -> np.ndarray:
        offset = 3.0 if (step // (2 * CONTROL_HZ)) % 2 else 0.0
        return np.column_stack(
            [grid[:, 0] + offset, grid[:, 1], np.zeros(n), np.full(n, ALTITUDE_M)]
        )

    step = 0
    for _ in range(CONTROL_HZ):  # 1 s of sim time to take off
        env.set_all_setpoints(setpoints(step))
        env.step()
        step += 1
    start = time.perf_counter()
    cpu0 = time.process_time()
    steps = 0
    while (elapsed := time.perf_counter() - start) < seconds:
        env.set_all_setpoints(setpoints(step))
        env.step()
        step += 1
        steps += 1
    cpu = time.process_time() - cpu0
    env.disconnect()
    rate = steps / elapsed
    print(
        json.dumps(
            {
                "steps": steps,
                "wall_s": round(elapsed, 3),
                "cpu_s": round(cpu, 3),
                "steps_per_s": round(rate, 1),
                "real_time_factor": round(rate / CONTROL_HZ, 3),
            }
        )
    )


if __name__ == "__main__":
    main()
