"""agents — one autopilot process per vehicle, and the ``Swarm`` client for swarm algorithms.

The client is loaded on first use (``from agents import Swarm`` works as before), so an
autopilot process, which imports ``agents.autopilot_node``, does not load it.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from agents.swarm import (
        ClockError,
        CommandRejected,
        CommandTimeout,
        PlumeError,
        RadioReadError,
        RadioSent,
        RadioUnavailable,
        Swarm,
        SwarmError,
        VehicleCommander,
        WaitTimeout,
    )

__all__ = [
    "ClockError",
    "CommandRejected",
    "CommandTimeout",
    "PlumeError",
    "RadioReadError",
    "RadioSent",
    "RadioUnavailable",
    "Swarm",
    "SwarmError",
    "VehicleCommander",
    "WaitTimeout",
]


def __getattr__(name: str) -> Any:
    if name in __all__:
        return getattr(importlib.import_module("agents.swarm"), name)
    raise AttributeError(f"module 'agents' has no attribute {name!r}")
