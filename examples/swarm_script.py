"""Fly a running swarm from a script: take off, fly into the plume, compare readings and model.

Start the stack first, in another terminal, on the stepped clock (the world moves only when
this script steps it, so every run gives the same numbers):

    plumeswarm up --stepped --headless

then run `python examples/swarm_script.py` (`--connect tcp/HOST:PORT` for another router).
"""

import argparse

from plumeswarm import Swarm

TARGETS = {"uav1": (40.0, -4.0, 10.0), "uav2": (40.0, 0.0, 10.0), "uav3": (40.0, 4.0, 10.0)}

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--connect", default="tcp/127.0.0.1:7447", help="the stack's router")
args = parser.parse_args()

with Swarm.connect(connect=[args.connect], command_timeout_s=20.0) as sw:
    sw.step(1)  # take the stepped clock: the world is paused at tick 1
    for vid in TARGETS:
        sw.command(vid).arm()
        sw.command(vid).takeoff(10.0)
    sw.step_until(lambda: all(sw.status(v).mode == "hold" for v in TARGETS), 40.0, "airborne")
    for vid, (x, y, z) in TARGETS.items():
        sw.command(vid).goto(x, y, z)  # downwind of the source, on and beside the centreline

    def arrived() -> bool:
        for vid, target in TARGETS.items():
            position = sw.state(vid).position_enu_m
            if sum((p - q) ** 2 for p, q in zip(position, target, strict=True)) > 0.5**2:
                return False
        return True

    sw.step_until(arrived, 60.0, "at the targets")
    sw.step(120)  # hover 1 s: several sensor readings at the target
    for vid in TARGETS:
        reading = sw.reading(vid)
        model = sw.plume.concentration([reading.position_enu_m])[0]
        x, y, z = reading.position_enu_m
        print(
            f"{vid} at ({x:.1f}, {y:.1f}, {z:.1f}) m reads {reading.reported_g_m3:.4f} g/m3, "
            f"the plume model there {model:.4f} g/m3"
        )
