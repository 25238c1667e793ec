"""The physics' log lines for participants dropped at a tick's deadline.

See docs/physics.md, "Lockstep" (rule 4) and "Restarts: the clock waits".
"""

from __future__ import annotations

import logging
from collections.abc import Collection, Sequence

from sim_world.plume_part import PLUME

log = logging.getLogger(__name__)


def report_dropped(
    tick: int,
    dropped: Sequence[str],
    held: Collection[str],
    timeout_s: float,
    grace_s: float,
    then: str = "motors off",
) -> None:
    """Log who tick ``tick`` dropped: silent vehicles (``then``: what becomes of them), the
    plume (its readings unavailable), held participants whose restart grace passed."""
    vehicles = [v for v in dropped if v != PLUME]
    if vehicles:
        log.warning(
            "tick %d: dropped %s after %.2f s without actuators (%s)",
            tick,
            ", ".join(vehicles),
            timeout_s,
            then,
        )
    if PLUME in dropped:
        log.warning(
            "tick %d: no plume sample after %.2f s: this sensor tick's readings are "
            "unavailable; the plume service takes part again once it answers a sensor tick",
            tick,
            timeout_s,
        )
    expired = [v for v in vehicles if v in held]
    if expired:
        log.warning(
            "tick %d: restart grace of %.1f s passed: %s dropped (motors off, failsafe)",
            tick,
            grace_s,
            ", ".join(expired),
        )
