"""``python -m plumeswarm.bench`` (``make bench``): run every benchmark script here, one table
each, and a short grid of ``plumeswarm bench scale``. The library modules the CLI calls
(``scale``, ``envs``) are not scripts; they run through ``plumeswarm bench``."""

from __future__ import annotations

import pkgutil
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def _is_script(path: Path) -> bool:
    return path.is_file() and 'if __name__ == "__main__":' in path.read_text()


def main() -> int:
    names = sorted(
        m.name
        for m in pkgutil.iter_modules([str(HERE)])
        if not m.name.startswith("_") and _is_script(HERE / f"{m.name}.py")
    )
    only = set(sys.argv[1:])
    failed = []
    for name in names:
        if only and name not in only:
            continue
        print(f"\n=== {__package__}.{name} ===", flush=True)
        res = subprocess.run([sys.executable, "-m", f"{__package__}.{name}"])
        if res.returncode != 0:
            failed.append(name)
    if not only or "scale" in only:
        print("\n=== plumeswarm bench scale (short grid) ===", flush=True)
        grid = ["--vehicles", "1,4,16", "--state", "grounded,hovering", "--seconds", "5"]
        res = subprocess.run([sys.executable, "-m", "plumeswarm", "bench", "scale", *grid])
        if res.returncode != 0:
            failed.append("scale")
    if failed:
        print(f"\nfailed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
