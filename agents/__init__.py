"""agents — one autopilot process per vehicle, and the ``Swarm`` client for swarm algorithms."""

from agents.swarm import (
    CommandRejected,
    CommandTimeout,
    PlumeError,
    Swarm,
    SwarmError,
    VehicleCommander,
    WaitTimeout,
)

__all__ = [
    "CommandRejected",
    "CommandTimeout",
    "PlumeError",
    "Swarm",
    "SwarmError",
    "VehicleCommander",
    "WaitTimeout",
]
