"""``python -m bench.scale``: the full stack's real-time factor and cost against vehicle count.

A short default grid (``make bench``: 1, 4, 16 vehicles, grounded and hovering, 5 s each) through
:func:`deploy.scale_bench.run_scale`; every option of the full bench is ``plumeswarm bench
scale`` (see docs/performance.md).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from deploy.scale_bench import ScaleError, ScaleOptions, run_scale
from swarmbus.scenario import ScenarioError, load_scenario, resolve_scenario_path


def _ints(value: str) -> tuple[int, ...]:
    try:
        out = tuple(int(v) for v in value.split(",") if v.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"{value!r} is not a list of integers") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"{value!r}: give at least one count, each >= 1")
    return out


def main() -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.scale", description=__doc__)
    ap.add_argument("--scenario", default=None, help="scenario file or name (default novak2018)")
    ap.add_argument("--vehicles", type=_ints, default=(1, 4, 16), help="comma-separated counts")
    ap.add_argument("--state", default="grounded,hovering", help="comma-separated states")
    ap.add_argument("--seconds", type=float, default=5.0, help="wall seconds measured per row")
    ap.add_argument("--out", type=Path, default=Path("runs/bench-scale"), help="output directory")
    args = ap.parse_args()
    try:
        scenario = load_scenario(resolve_scenario_path(args.scenario))
    except ScenarioError as exc:
        print(f"bench.scale: error: {exc}", file=sys.stderr)
        return 2
    opts = ScaleOptions(
        scenario=scenario,
        out=args.out,
        vehicles=args.vehicles,
        states=tuple(s.strip() for s in args.state.split(",") if s.strip()),
        seconds=args.seconds,
    )
    try:
        rows = run_scale(opts)
    except ScaleError as exc:
        print(f"bench.scale: error: {exc}", file=sys.stderr)
        return 2
    return 1 if any("error" in r for r in rows) else 0


if __name__ == "__main__":
    sys.exit(main())
