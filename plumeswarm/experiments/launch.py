"""How the user layer starts the stack's processes: each role runs as ``python -m plumeswarm node
ROLE …`` (docs/architecture.md, "Layers"); the launcher is handed this command."""

from __future__ import annotations

import sys

NODE_COMMAND: tuple[str, ...] = (sys.executable, "-m", "plumeswarm")
