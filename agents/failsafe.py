"""Failsafe monitor: ground-control link loss, geofence, crash.

Each failsafe fires on the edge (link lost, fence crossed outwards, crash reported), applies the
configured action through :meth:`agents.modes.FlightModes.failsafe_action` and leaves the pilot
free to command something else afterwards. Time is simulated time.

Link-loss semantics: the timer only runs once a ground station was seen (a ``GcsHeartbeat``
command arrived), so a swarm run without a GCS never trips it; with
``failsafe.datalink_required`` arming is refused until a heartbeat is fresh.
"""

from __future__ import annotations

from agents.control import Estimate
from agents.mode_table import AIRBORNE
from agents.modes import FlightModes

DATALINK_LOST = "ground-control link lost"


class FailsafeMonitor:
    def __init__(self, modes: FlightModes) -> None:
        self.modes = modes
        self.gcs_seen = False
        self.last_gcs_s = 0.0
        self.datalink_lost = False
        self.outside_fence = False
        self.crashed = False

    def heartbeat(self, now: float) -> None:
        self.gcs_seen = True
        self.last_gcs_s = now
        if self.datalink_lost:
            self.datalink_lost = False
            if self.modes.failsafe_reason == DATALINK_LOST:
                self.modes.failsafe_reason = ""

    def gcs_link_ok(self, now: float) -> bool:
        return self.gcs_seen and now - self.last_gcs_s <= self.modes.failsafe.datalink_timeout_s

    def check(self, est: Estimate, crashed: bool, now: float) -> None:
        modes = self.modes
        if crashed:
            if not self.crashed:
                self.crashed = True
                modes.crashed(est)
            return
        cfg = modes.failsafe
        if (
            self.gcs_seen
            and not self.datalink_lost
            and now - self.last_gcs_s > cfg.datalink_timeout_s
        ):
            self.datalink_lost = True
            modes.failsafe_action(cfg.datalink_loss_action, est, DATALINK_LOST)
        if modes.mode not in AIRBORNE:
            self.outside_fence = False
            return
        violation = modes.fence_violation(*est.position)
        if violation is not None and not self.outside_fence:
            modes.failsafe_action("rtl", est, f"geofence: {violation}")
        self.outside_fence = violation is not None
