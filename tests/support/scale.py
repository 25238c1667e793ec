"""The sizes the fault tests fly: the three vehicles, one per autopilot process, and 32 in 4
autopilot processes of 8 under the marker ``scale`` (``make test-scale``; not in ``make test``'s
main suite: each such test takes minutes)."""

from __future__ import annotations

from collections.abc import Sequence

import pytest

Shape = tuple[tuple[str, ...], int]  # the vehicles, how many each autopilot process serves


def fleet(n: int) -> tuple[str, ...]:
    """The ids ``uav1`` .. ``uav<n>`` (those of the seed scenario, and of it scaled by
    ``deploy.scaling``)."""
    return tuple(f"uav{k}" for k in range(1, n + 1))


def patience(vehicles: Sequence[str]) -> float:
    """How many times the three vehicles' timeouts (waits, the physics' start-up timeout) a
    stack of ``vehicles`` gets: one more for every 8 vehicles past 8 (32 start and fly slower)."""
    return max(1.0, len(vehicles) / 8)


def process_of(vehicles: Sequence[str], per_process: int) -> dict[str, list[str]]:
    """Each vehicle's autopilot process's vehicles, as the launcher groups them (in order)."""
    groups = [list(vehicles[i : i + per_process]) for i in range(0, len(vehicles), per_process)]
    return {vid: group for group in groups for vid in group}


THREE: Shape = (fleet(3), 1)
SHAPES = [
    pytest.param(THREE, id="3"),
    pytest.param(
        (fleet(32), 8),
        id="32-in-groups-of-8",
        marks=[pytest.mark.scale, pytest.mark.timeout(3600)],
    ),
]
