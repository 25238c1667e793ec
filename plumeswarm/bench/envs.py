"""``plumeswarm bench envs``: how fast the environments step, fused and on the bus, side by side.

For every backend and vehicle count N: a :class:`~plumeswarm.envs.swarm.PlumeSwarmEnv` on the
scenario scaled to N vehicles, ``reset(seed=0)`` (start-up and take-off, timed apart), then
``steps`` steps in which every agent holds still (zero velocity, zero yaw rate: the autopilots
and the physics do their full work). Per row: steps per second and the real-time factor (sim
time advanced over wall time) of those steps, the reset's wall time, and for the fused backend
the real-time factor per CPU second of this process (what one idle core would give: on a
shared machine the wall-clock numbers mostly measure the others' load, printed beside them).
The bus backend starts a stack per reset on the stepped clock and grants each step's ticks in
one request (after one command query per agent), so its rows show what the bus costs over the
fused backend's. Rows go to ``DIR/envs.json``.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from plumeswarm.envs.swarm import PlumeSwarmEnv
from plumeswarm.experiments.driver import Driver, open_driver
from swarmbus.scenario import Scenario

BACKENDS = ("fused", "bus")


@dataclass(frozen=True)
class EnvBenchOptions:
    scenario: Scenario
    out: Path
    vehicles: Sequence[int] = (1, 3, 16, 64)
    backends: Sequence[str] = BACKENDS
    steps: int = 30
    ticks_per_step: int = 12
    vehicles_per_process: int = 1


def _backend(name: str, opts: EnvBenchOptions) -> Driver:
    return open_driver(name, vehicles_per_process=opts.vehicles_per_process)


def measure(opts: EnvBenchOptions, backend: str, vehicles: int) -> dict[str, Any]:
    env = PlumeSwarmEnv(
        opts.scenario,
        vehicles=vehicles,
        backend=_backend(backend, opts),
        ticks_per_step=opts.ticks_per_step,
    )
    try:
        t0 = time.perf_counter()
        env.reset(seed=0)
        reset_s = time.perf_counter() - t0
        hold = {a: np.zeros(4, dtype=np.float32) for a in env.possible_agents}
        sim0 = env.backend.states()[env.possible_agents[0]].sim_time_s
        t0 = time.perf_counter()
        cpu0 = time.process_time()
        steps = 0
        while steps < opts.steps and env.agents:
            env.step(hold)
            steps += 1
        wall = time.perf_counter() - t0
        cpu = time.process_time() - cpu0
        sim = env.backend.states()[env.possible_agents[0]].sim_time_s - sim0
    finally:
        env.close()
    return {
        "backend": backend,
        "vehicles": vehicles,
        "steps_per_s": steps / wall,
        "real_time_factor": sim / wall,
        "ticks_per_step": opts.ticks_per_step,
        "steps": steps,
        "reset_s": reset_s,
        # fused: all the work is this process's, so sim time over its CPU time is the
        # real-time factor on one otherwise idle core (a shared machine's load drops out)
        "cpu_real_time_factor": sim / cpu if backend == "fused" and cpu > 0 else None,
        "load_average_1m": os.getloadavg()[0],
    }


def table(rows: Sequence[dict[str, Any]]) -> list[str]:
    lines = [
        f"{'vehicles':>8}  {'backend':<6} {'steps/s':>9} {'RTF':>8} {'RTF/CPU':>8} "
        f"{'reset s':>8} {'load':>5}",
    ]
    for row in sorted(rows, key=lambda r: (r["vehicles"], BACKENDS.index(r["backend"]))):
        if "error" in row:
            lines.append(f"{row['vehicles']:>8}  {row['backend']:<6} error: {row['error']}")
            continue
        cpu_rtf = row["cpu_real_time_factor"]
        cpu_text = f"{cpu_rtf:>7.2f}x" if cpu_rtf is not None else f"{'-':>8}"
        lines.append(
            f"{row['vehicles']:>8}  {row['backend']:<6} {row['steps_per_s']:>9.1f} "
            f"{row['real_time_factor']:>7.2f}x {cpu_text} {row['reset_s']:>8.2f} "
            f"{row['load_average_1m']:>5.1f}"
        )
    return lines


def run_env_bench(
    opts: EnvBenchOptions, echo: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    unknown = [b for b in opts.backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"--backends: unknown {', '.join(unknown)}; known: fused, bus")
    opts.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    for n in opts.vehicles:
        for backend in opts.backends:
            echo(f"{backend}, {n} vehicle(s): reset and {opts.steps} steps …")
            try:
                row = measure(opts, backend, n)
            except Exception as exc:  # one failed row must not lose the others
                row = {"backend": backend, "vehicles": n, "error": str(exc)[:300]}
            rows.append(row)
            (opts.out / "envs.json").write_text(json.dumps(rows, indent=2) + "\n")
    for line in table(rows):
        echo(line)
    echo(f"written: {opts.out / 'envs.json'}")
    return rows
