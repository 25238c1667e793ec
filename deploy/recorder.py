"""``plumeswarm node recorder``: the recorder role (see :mod:`deploy.recording.recorder`)."""

from __future__ import annotations

from deploy.recording.recorder import run
from swarmbus.node import NodeContext


def main(ctx: NodeContext) -> int:
    """Record every message of ``ctx``'s world to ``--set out=FILE`` until stopped."""
    return run(ctx)
