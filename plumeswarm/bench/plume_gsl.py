"""What a GSL benchmark episode pays for its plume: per environment (swarmbus/scenarios/gsl/),
the field at one vehicle position every 0.1 s of sim time.

Run with ``python -m plumeswarm.bench.plume_gsl [--out FILE.json] [--repeats N] [--ticks N]``. For
each
environment, after its warm-up: the mean time of a tick (advance the plume 0.1 s and evaluate
one point) over ``--ticks`` consecutive ticks, and of one more evaluation at the same time
(the field already advanced); the best of ``--repeats`` blocks (the machine may be shared).
Prints a table and writes JSON (default ``runs/bench-plume-gsl.json``).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from plume_service.filament import FilamentPlume
from plume_service.from_scenario import field_from_scenario
from plume_service.statistics import warmup_s
from swarmbus.scenario import GSL_ENVIRONMENTS_DIR, load_scenario

REPO = Path(__file__).resolve().parent.parent
TICK_S = 0.1


def measure(name: str, repeats: int, ticks: int) -> dict[str, float]:
    scenario = load_scenario(GSL_ENVIRONMENTS_DIR / f"{name}.toml")
    field = field_from_scenario(scenario)
    t = warmup_s(scenario)
    point = [[50.0, 0.0, 10.0]]
    field.concentration(point, t)
    best_tick = best_eval = float("inf")
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(ticks):
            t += TICK_S
            field.concentration(point, t)
        best_tick = min(best_tick, (time.perf_counter() - start) / ticks)
        start = time.perf_counter()
        for k in range(ticks):
            field.concentration([[50.0, 0.01 * k, 10.0]], t)
        best_eval = min(best_eval, (time.perf_counter() - start) / ticks)
    live = 0.0
    if isinstance(field, FilamentPlume):
        live = float(field.filaments(t)[0].shape[0])
    return {"tick_ms": best_tick * 1e3, "evaluation_ms": best_eval * 1e3, "filaments": live}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--ticks", type=int, default=200)
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "bench-plume-gsl.json")
    args = parser.parse_args()
    names = sorted(p.stem for p in GSL_ENVIRONMENTS_DIR.glob("*.toml"))
    results = {name: measure(name, args.repeats, args.ticks) for name in names}
    print(f"{'environment':24}{'tick (ms)':>11}{'evaluation (ms)':>17}{'filaments':>11}")
    for name, r in results.items():
        print(f"{name:24}{r['tick_ms']:11.3f}{r['evaluation_ms']:17.3f}{r['filaments']:11.0f}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
