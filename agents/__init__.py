"""agents — one autopilot process per vehicle, and the ``Swarm`` client for swarm algorithms."""

from agents.swarm import (
    ClockError,
    CommandRejected,
    CommandTimeout,
    PlumeError,
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
    "Swarm",
    "SwarmError",
    "VehicleCommander",
    "WaitTimeout",
]
