"""``python -m plumeswarm.bench.pyflyt``: plumeswarm against PyFlyt at the same N, side by side in
one run.

PyFlyt (a single-process pybullet drone simulator; quadx, 240 Hz physics, 120 Hz control, the
same rates as plumeswarm's default scenario) is not a dependency of plumeswarm: this bench
installs it into a virtualenv of its own (``--venv``, default ``runs/pyflyt-venv``; created on
first use, ``pyflyt==0.29.0``) and runs ``plumeswarm/bench/_pyflyt_aviary.py`` there. For every N it
measures, back to back, PyFlyt's ``Aviary`` (N drones flying position setpoints) and
plumeswarm's distributed stack flying (``plumeswarm bench scale --state flying``: router,
plume, physics, N autopilots with K per process, gateway), and prints both real-time factors
and their ratio. Output: a table on the terminal and ``DIR/pyflyt.json`` (rows: ``vehicles``,
``pyflyt_steps_per_s``, ``pyflyt_real_time_factor``, ``plumeswarm_ticks_per_s``,
``plumeswarm_real_time_factor``, ``vehicles_per_process``, ``ratio``, ``load1``).

    python -m plumeswarm.bench.pyflyt [--vehicles 1,3,16,64] [--vehicles-per-process K] [--seconds
    10]
                           [--out DIR] [--venv DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

from plumeswarm.bench.scale import ScaleError, ScaleOptions, run_case
from swarmbus.errors import PlumeswarmError
from swarmbus.scenario import load_scenario, resolve_scenario_path

HERE = Path(__file__).resolve().parent
PYFLYT = "pyflyt==0.29.0"


class BenchError(PlumeswarmError, RuntimeError):
    pass


def ensure_venv(venv: Path) -> Path:
    """The virtualenv's python, with PyFlyt installed (created and installed on first use)."""
    python = venv / "bin" / "python"
    if python.exists() and _run([str(python), "-c", "import PyFlyt"]).returncode == 0:
        return python
    print(f"installing {PYFLYT} into {venv} (first use; a few minutes)", flush=True)
    for cmd in (
        [sys.executable, "-m", "venv", str(venv)],
        [str(python), "-m", "pip", "install", "-q", PYFLYT],
    ):
        res = _run(cmd)
        if res.returncode != 0:
            raise BenchError(f"{' '.join(cmd)} failed: {res.stderr.strip()[-400:]}")
    return python


def _run(cmd: list[str], timeout_s: float = 900.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)


def pyflyt_row(python: Path, n: int, seconds: float) -> dict[str, Any]:
    res = _run([str(python), str(HERE / "_pyflyt_aviary.py"), str(n), str(seconds)])
    lines = [ln for ln in res.stdout.splitlines() if ln.startswith("{")]
    if res.returncode != 0 or not lines:
        raise BenchError(f"PyFlyt with {n} drones failed: {res.stderr.strip()[-400:]}")
    row: dict[str, Any] = json.loads(lines[-1])
    return row


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m plumeswarm.bench.pyflyt", description=__doc__.split("\n")[0]
    )
    p.add_argument("--vehicles", default="1,3,16,64", help="comma-separated counts")
    p.add_argument("--vehicles-per-process", type=int, default=1, help="plumeswarm's K")
    p.add_argument("--seconds", type=float, default=10.0, help="wall time measured per run")
    p.add_argument("--out", type=Path, default=Path("runs/bench-pyflyt"))
    p.add_argument("--venv", type=Path, default=Path("runs/pyflyt-venv"))
    a = p.parse_args(argv)
    try:
        counts = [int(v) for v in a.vehicles.split(",") if v.strip()]
    except ValueError:
        p.error(f"--vehicles {a.vehicles!r} is not a comma-separated list of integers")
    if not counts or min(counts) < 1 or a.vehicles_per_process < 1 or a.seconds <= 0:
        p.error("--vehicles, --vehicles-per-process and --seconds must be positive")
    a.out.mkdir(parents=True, exist_ok=True)
    opts = ScaleOptions(
        scenario=load_scenario(resolve_scenario_path(None)),
        out=a.out,
        seconds=a.seconds,
        vehicles_per_process=a.vehicles_per_process,
    )
    rows: list[dict[str, Any]] = []
    try:
        python = ensure_venv(a.venv.resolve())
        for n in counts:
            print(f"{n} vehicles: PyFlyt …", flush=True)
            fly = pyflyt_row(python, n, a.seconds)
            print(f"{n} vehicles: plumeswarm …", flush=True)
            ours = run_case(opts, n, "flying")
            rows.append(
                {
                    "vehicles": n,
                    "pyflyt_steps_per_s": fly["steps_per_s"],
                    "pyflyt_real_time_factor": fly["real_time_factor"],
                    "plumeswarm_ticks_per_s": ours["ticks_per_s"],
                    "plumeswarm_real_time_factor": ours["real_time_factor"],
                    "vehicles_per_process": a.vehicles_per_process,
                    "ratio": round(ours["real_time_factor"] / fly["real_time_factor"], 3),
                    "load1": round(os.getloadavg()[0], 2),
                }
            )
            (a.out / "pyflyt.json").write_text(json.dumps(rows, indent=2) + "\n")
    except (BenchError, ScaleError, subprocess.TimeoutExpired) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(table(rows))
    print(f"written: {a.out / 'pyflyt.json'}")
    return 0


def table(rows: list[dict[str, Any]]) -> str:
    lines = [
        "| N | PyFlyt steps/s | PyFlyt RTF | plumeswarm ticks/s | plumeswarm RTF | K | "
        "plumeswarm / PyFlyt | load1 |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['vehicles']} | {r['pyflyt_steps_per_s']:.0f} | "
            f"{r['pyflyt_real_time_factor']:.2f} | {r['plumeswarm_ticks_per_s']:.0f} | "
            f"{r['plumeswarm_real_time_factor']:.2f} | {r['vehicles_per_process']} | "
            f"{r['ratio']:.2f} | {r['load1']:.1f} |"
        )
    return "\n".join(lines)


if __name__ == "__main__":
    sys.exit(main())
