"""Dynamic plume benchmarks: filaments and puffs side by side with the Gaussian plume.

Run with ``python -m plumeswarm.bench.plume_dynamic [--out FILE.json] [--repeats N]``. Prints one
table
and writes the same numbers as JSON (default ``runs/bench-plume-dynamic.json``):

* advancing a plume of ~3000 live filaments (50 Hz release, 60 s lifetime, meandering wind)
  one internal step, and ~1200 puffs (0.5 s period, 600 s lifetime) one step;
* answering a query for 3 and for 256 points at a fresh step (the filament query includes the
  k-d tree a 256-point query builds once per step), against the Gaussian plume's;
* one evaluation of the meandering wind; the same wind with ``[wind.turbulence]`` (32 modes)
  at one and at 2000 points, and the filaments advanced one step in it.

Times are the best of ``--repeats`` runs (the machine may be shared).
"""

from __future__ import annotations

import argparse
import json
from functools import partial
from pathlib import Path

import msgspec
import numpy as np

from plume_atmosphere.wind import wind_model
from plume_service import GaussianPlume
from plume_service.filament import FilamentPlume, filament_concentration
from plume_service.puff import PuffPlume
from plumeswarm.bench.plume import best_seconds
from swarmbus.scenario import PlumeFilament, PlumePuff, Wind, WindMeander, WindTurbulence

REPO = Path(__file__).resolve().parent.parent


def query_points(count: int, seed: int = 0) -> np.ndarray:
    """Points where the plumes are: 5–60 m downwind, ±5 m across, 0–10 m up."""
    rng = np.random.default_rng(seed)
    return rng.uniform([5.0, -5.0, 0.0], [60.0, 5.0, 10.0], size=(count, 3))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--out", type=Path, default=REPO / "runs" / "bench-plume-dynamic.json")
    args = parser.parse_args()
    repeats = args.repeats
    meander = Wind(speed_m_s=2.0, model="meander", meander=WindMeander(preset="small"))
    wind = wind_model(meander, seed=1)
    params = PlumeFilament(release_rate_hz=50.0, max_age_s=60.0)
    filaments = FilamentPlume((0.0, 0.0, 5.0), 10.0, params, wind, seed=1)
    t = 65.0
    k, state = filaments.state_at(t)
    rng = np.random.default_rng(0)
    live = state.birth_step.shape[0]
    step_s = best_seconds(lambda: filaments.advance(state, k, rng), repeats)
    radii = filaments.radii(state, k)
    masses = np.full(live, filaments.mass_g)
    results: dict[str, float] = {
        "filaments_live": float(live),
        "filament_step_ms": step_s * 1e3,
    }
    puffs = PuffPlume((0.0, 0.0, 5.0), 10.0, PlumePuff(), wind_model(Wind(), 1), seed=1)
    pk, pstate = puffs.state_at(610.0)
    results["puffs_live"] = float(pstate.index.shape[0])
    results["puff_step_ms"] = 1e3 * best_seconds(lambda: puffs.advance(pstate, pk, rng), repeats)
    gaussian = GaussianPlume(10.0, 6.0, 5.0)
    for count in (3, 256):
        points = query_points(count)
        results[f"filament_query_{count}_ms"] = 1e3 * best_seconds(
            partial(filament_concentration, points, state.positions, radii, masses),
            repeats,
        )
        results[f"puff_query_{count}_ms"] = 1e3 * best_seconds(
            partial(puffs.concentration, points, 610.0), repeats
        )
        results[f"gaussian_query_{count}_ms"] = 1e3 * best_seconds(
            partial(gaussian.concentration, points), repeats
        )
    one = query_points(1)
    results["meander_wind_query_us"] = 1e6 * best_seconds(lambda: wind.velocity(one, t), repeats)
    # the meander with local turbulence (share 0.3 of class D at 2 m/s, 5 m: derived values)
    turbulence = WindTurbulence(
        std_m_s=(0.164, 0.123, 0.078), length_scale_m=7.92, timescale_s=9.40, modes=32
    )
    turbulent = wind_model(msgspec.structs.replace(meander, turbulence=turbulence), seed=1)
    many = query_points(2000)
    results["turbulent_wind_query_us"] = 1e6 * best_seconds(
        lambda: turbulent.velocity(one, t), repeats
    )
    results["turbulent_wind_query_2000_ms"] = 1e3 * best_seconds(
        lambda: turbulent.velocity(many, t), repeats
    )
    stirred = FilamentPlume((0.0, 0.0, 5.0), 10.0, params, turbulent, seed=1)
    sk, sstate = stirred.state_at(t)
    results["turbulent_filaments_live"] = float(sstate.birth_step.shape[0])
    results["turbulent_filament_step_ms"] = 1e3 * best_seconds(
        lambda: stirred.advance(sstate, sk, rng), repeats
    )

    rows = [
        (f"filament plume: advance {live} live filaments one step", "filament_step_ms", "ms"),
        ("filament plume: query 3 points", "filament_query_3_ms", "ms"),
        ("filament plume: query 256 points (k-d tree built)", "filament_query_256_ms", "ms"),
        (f"puff plume: advance {int(results['puffs_live'])} puffs one step", "puff_step_ms", "ms"),
        ("puff plume: query 3 points", "puff_query_3_ms", "ms"),
        ("puff plume: query 256 points", "puff_query_256_ms", "ms"),
        ("Gaussian plume: query 3 points", "gaussian_query_3_ms", "ms"),
        ("Gaussian plume: query 256 points", "gaussian_query_256_ms", "ms"),
        ("meander wind: one point", "meander_wind_query_us", "µs"),
        ("meander wind with turbulence: one point", "turbulent_wind_query_us", "µs"),
        ("meander wind with turbulence: 2000 points", "turbulent_wind_query_2000_ms", "ms"),
        (
            f"filament plume, turbulent wind: advance "
            f"{int(results['turbulent_filaments_live'])} filaments one step",
            "turbulent_filament_step_ms",
            "ms",
        ),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'dynamic plume benchmark (best of ' + str(repeats) + ')':<{width}}  result")
    print(f"{'-' * width}  ------")
    for label, key, unit in rows:
        print(f"{label:<{width}}  {results[key]:.3f} {unit}")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(results, indent=2) + "\n")
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
