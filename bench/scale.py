"""``python -m bench.scale``: the full stack's real-time factor and cost against vehicle count.

A short default grid (``make bench``); the full one is ``plumeswarm bench scale`` (see
docs/performance.md). Extra arguments go to ``plumeswarm bench scale`` unchanged.
"""

from __future__ import annotations

import sys

from deploy.cli import cli

DEFAULT = ["--vehicles", "1,4,16", "--state", "grounded,hovering", "--seconds", "5"]


def main() -> None:
    args = sys.argv[1:] or DEFAULT
    cli(["bench", "scale", *args, *(["--out", "runs/bench-scale"] if "--out" not in args else [])])


if __name__ == "__main__":
    main()
