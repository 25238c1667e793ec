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
fused backend's.

Two references beside them, for the fused backend's ratios (one table per run, every row of it
measured in the same minutes): ``pyflyt``, PyFlyt's ``Aviary`` with N drones flying position
setpoints (:mod:`plumeswarm.bench.pyflyt`: its own virtualenv, ``pyflyt_seconds`` of wall time),
and ``floor``, the same pybullet bodies stepped with nothing but one pose and velocity read,
one force and one torque per vehicle and physics step (:mod:`plumeswarm.bench.pybullet_floor`,
as many ticks as the fused rows step). Ratios are of real-time factors per CPU second (what one
idle core gives each; on a shared machine the wall-clock factors move with the others' load).
Rows go to ``DIR/envs.json``.
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

from deploy.scaling import scale_scenario
from plumeswarm.bench.pybullet_floor import floor_row
from plumeswarm.bench.pyflyt import ensure_venv, pyflyt_row
from plumeswarm.envs.swarm import PlumeSwarmEnv
from plumeswarm.experiments.driver import Driver, open_driver
from swarmbus.scenario import Scenario

BACKENDS = ("fused", "bus", "pyflyt", "floor")


@dataclass(frozen=True)
class EnvBenchOptions:
    scenario: Scenario
    out: Path
    vehicles: Sequence[int] = (1, 3, 16, 64)
    backends: Sequence[str] = BACKENDS
    steps: int = 30
    ticks_per_step: int = 12
    vehicles_per_process: int = 1
    pyflyt_seconds: float = 4.0
    pyflyt_venv: Path = Path("runs/pyflyt-venv")


def _backend(name: str, opts: EnvBenchOptions) -> Driver:
    return open_driver(name, vehicles_per_process=opts.vehicles_per_process)


def measure(opts: EnvBenchOptions, backend: str, vehicles: int) -> dict[str, Any]:
    if backend in ("pyflyt", "floor"):
        return measure_reference(opts, backend, vehicles)
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


def measure_reference(opts: EnvBenchOptions, backend: str, vehicles: int) -> dict[str, Any]:
    """A PyFlyt or pybullet-floor row, in the fields of the environments' rows."""
    if backend == "pyflyt":
        fly = pyflyt_row(ensure_venv(opts.pyflyt_venv.resolve()), vehicles, opts.pyflyt_seconds)
        control_hz = 120.0  # the aviary's: two 240 Hz physics steps per step()
        steps, wall, cpu = fly["steps"], fly["wall_s"], fly["cpu_s"]
        sim = steps / control_hz
    else:
        scenario = scale_scenario(opts.scenario, vehicles)
        steps = opts.steps * opts.ticks_per_step
        floor = floor_row(scenario, steps)
        wall, cpu, sim = floor["wall_s"], floor["cpu_s"], floor["sim_s"]
    return {
        "backend": backend,
        "vehicles": vehicles,
        "steps_per_s": steps / wall,  # a reference row's steps are control ticks
        "real_time_factor": sim / wall,
        "ticks_per_step": 1,
        "steps": steps,
        "reset_s": None,
        "cpu_real_time_factor": sim / cpu if cpu > 0 else None,
        "load_average_1m": os.getloadavg()[0],
    }


def ratios(rows: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per vehicle count with a fused row: its CPU real-time factor over PyFlyt's and over the
    floor's, where those rows are there."""
    cpu_rtf = {
        (r["backend"], r["vehicles"]): r["cpu_real_time_factor"]
        for r in rows
        if "error" not in r and r.get("cpu_real_time_factor")
    }
    out = []
    for n in sorted({r["vehicles"] for r in rows}):
        fused = cpu_rtf.get(("fused", n))
        if fused is None:
            continue
        row: dict[str, Any] = {"vehicles": n, "fused_cpu_real_time_factor": fused}
        for ref in ("pyflyt", "floor"):
            other = cpu_rtf.get((ref, n))
            row[f"fused_over_{ref}"] = fused / other if other else None
        out.append(row)
    return out


def ratio_table(rows: Sequence[dict[str, Any]]) -> list[str]:
    lines = [f"{'vehicles':>8}  {'fused RTF/CPU':>13} {'/ PyFlyt':>9} {'/ floor':>8}"]
    for r in ratios(rows):
        cells = [
            f"{r[key]:>8.2f}x" if r[key] is not None else f"{'-':>9}"
            for key in ("fused_over_pyflyt", "fused_over_floor")
        ]
        fused = r["fused_cpu_real_time_factor"]
        lines.append(f"{r['vehicles']:>8}  {fused:>12.2f}x {' '.join(cells)}")
    return lines


def table(rows: Sequence[dict[str, Any]]) -> list[str]:
    lines = [
        f"{'vehicles':>8}  {'backend':<6} {'steps/s':>9} {'RTF':>8} "
        f"{'RTF/CPU':>8} "
        f"{'reset s':>8} {'load':>5}",
    ]
    for row in sorted(rows, key=lambda r: (r["vehicles"], BACKENDS.index(r["backend"]))):
        if "error" in row:
            lines.append(f"{row['vehicles']:>8}  {row['backend']:<6} error: {row['error']}")
            continue
        cpu_rtf = row["cpu_real_time_factor"]
        cpu_text = f"{cpu_rtf:>7.2f}x" if cpu_rtf is not None else f"{'-':>8}"
        reset = row["reset_s"]
        reset_text = f"{reset:>8.2f}" if reset is not None else f"{'-':>8}"
        lines.append(
            f"{row['vehicles']:>8}  {row['backend']:<6} {row['steps_per_s']:>9.1f} "
            f"{row['real_time_factor']:>7.2f}x {cpu_text} {reset_text} "
            f"{row['load_average_1m']:>5.1f}"
        )
    return lines


def run_env_bench(
    opts: EnvBenchOptions, echo: Callable[[str], None] = print
) -> list[dict[str, Any]]:
    unknown = [b for b in opts.backends if b not in BACKENDS]
    if unknown:
        raise ValueError(f"--backends: unknown {', '.join(unknown)}; known: {', '.join(BACKENDS)}")
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
    if any(r["backend"] in ("pyflyt", "floor") for r in rows):
        for line in ratio_table(rows):
            echo(line)
    echo(f"written: {opts.out / 'envs.json'}")
    return rows
