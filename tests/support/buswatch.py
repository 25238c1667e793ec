"""What the vehicles really did, seen on the bus: every status and state, per vehicle."""

from __future__ import annotations

import threading
from typing import Any

import zenoh

from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys
from swarmbus.messages import VehicleState, VehicleStatus


class BusWatch:
    """Subscribes ``vehicle/<id>/status`` and ``/state``; ``mark()`` starts a new window."""

    def __init__(self, session: zenoh.Session, vehicle_ids: list[str], keys: Keys | None = None):
        keys = keys or Keys()
        self._lock = threading.Lock()
        self.statuses: dict[str, list[VehicleStatus]] = {v: [] for v in vehicle_ids}
        self.states: dict[str, list[VehicleState]] = {v: [] for v in vehicle_ids}
        self._subs: list[Any] = []
        for vid in vehicle_ids:
            self._subs.append(
                session.declare_subscriber(keys.vehicle_status(vid), self._on(vid, VehicleStatus))
            )
            self._subs.append(
                session.declare_subscriber(keys.vehicle_state(vid), self._on(vid, VehicleState))
            )

    def _on(self, vid: str, kind: type) -> Any:
        store = self.statuses if kind is VehicleStatus else self.states

        def callback(sample: zenoh.Sample) -> None:
            try:
                msg: Any = decode(sample.payload.to_bytes(), kind)
            except MessageError:
                return
            with self._lock:
                store[vid].append(msg)

        return callback

    def mark(self) -> None:
        """Forget everything seen so far (the window of interest starts now)."""
        with self._lock:
            for d in (self.statuses, self.states):
                for v in d.values():
                    v.clear()

    def status_window(self, vid: str) -> list[VehicleStatus]:
        with self._lock:
            return list(self.statuses[vid])

    def state_window(self, vid: str) -> list[VehicleState]:
        with self._lock:
            return list(self.states[vid])

    def latest_status(self, vid: str) -> VehicleStatus | None:
        with self._lock:
            return self.statuses[vid][-1] if self.statuses[vid] else None

    def spread_m(self, vid: str) -> float:
        """The largest distance of any state in the window from the window's first one."""
        states = self.state_window(vid)
        if not states:
            return 0.0
        x0 = states[0].position_enu_m
        return max(
            sum((a - b) ** 2 for a, b in zip(s.position_enu_m, x0, strict=True)) ** 0.5
            for s in states
        )

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
