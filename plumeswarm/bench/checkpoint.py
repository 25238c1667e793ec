"""Benchmark of the physics checkpoints: what one costs, and where.

``python -m plumeswarm.bench.checkpoint [--sizes 3,32,128] [--repeat 30]`` prints one markdown
table: for
N Iris quadcopters (half resting on the ground, half hovering), the time to capture the world
(:meth:`World.checkpoint`: pybullet ``saveBullet`` into RAM + motor state; the physics loop
pays this at each checkpoint tick), to write the file (msgpack + temporary file + rename into
a run directory; the checkpoint thread pays this, the loop only if it outlasts one tick), to
restore it in a fresh world (the restarted process pays this once), and the file size.
Medians and maxima over ``--repeat`` checkpoints.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from sim_world import checkpoint
from sim_world.world import World
from swarmbus.scenario import Scenario, parse_scenario


def scenario(n: int) -> Scenario:
    lines = ["[time]\nphysics_hz = 240\ncontrol_hz = 120\n"]
    for i in range(n):
        z = 0.0 if i % 2 == 0 else 20.0
        lines.append(f'[[vehicles]]\nid = "v{i}"\nspawn_enu_m = [{3.0 * i}, 0.0, {z}]\n')
    return parse_scenario("\n".join(lines))


def ms(values: list[float]) -> str:
    return f"{1e3 * statistics.median(values):.2f} / {1e3 * max(values):.2f}"


def row(n: int, repeat: int, run_dir: Path) -> str:
    sc = scenario(n)
    path = run_dir / f"physics-{n}.ckpt"
    capture: list[float] = []
    write: list[float] = []
    restore: list[float] = []
    with World(sc) as world:
        for i in range(repeat):
            world.step(2)
            t0 = time.perf_counter()
            cp = world.checkpoint(tick=i)
            t1 = time.perf_counter()
            checkpoint.save(path, cp)
            capture.append(t1 - t0)
            write.append(time.perf_counter() - t1)
    with World(sc) as fresh:
        for _ in range(max(3, repeat // 5)):
            t0 = time.perf_counter()
            fresh.restore(checkpoint.load(path))
            restore.append(time.perf_counter() - t0)
    size_kb = path.stat().st_size / 1024
    return f"| {n} | {ms(capture)} | {ms(write)} | {ms(restore)} | {size_kb:.0f} |"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", default="3,32,128")
    parser.add_argument("--repeat", type=int, default=30)
    args = parser.parse_args()
    print("| N | capture ms (median / max) | write ms | restore ms | file KB |")
    print("|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory(prefix="bench-checkpoint-", dir=".") as tmp:
        for n in (int(s) for s in args.sizes.split(",")):
            print(row(n, args.repeat, Path(tmp)), flush=True)


if __name__ == "__main__":
    main()
