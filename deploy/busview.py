"""What the bus says right now: clock, nodes, and each vehicle's state, status and reading.

A :class:`BusView` subscribes (callbacks only store the latest payload; decoding happens when
someone asks) and gives consistent snapshots to the launcher's status line, ``plumeswarm status``
and the demo's live table.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

import zenoh

from swarmbus.codec import decode_or_none
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import (
    Clock,
    ConcentrationReading,
    NodeHealth,
    VehicleState,
    VehicleStatus,
)
from swarmbus.session import Presence

log = logging.getLogger(__name__)
M = TypeVar("M")


@dataclass(frozen=True)
class VehicleView:
    vehicle_id: str
    state: VehicleState | None
    status: VehicleStatus | None
    reading: ConcentrationReading | None

    @property
    def position(self) -> tuple[float, float, float] | None:
        return self.state.position_enu_m if self.state is not None else None

    @property
    def flying(self) -> bool:
        if self.status is not None:
            return self.status.armed and not self.status.landed
        return self.state is not None and not self.state.on_ground


@dataclass(frozen=True)
class Snapshot:
    clock: Clock | None
    alive: frozenset[str]
    health: dict[str, NodeHealth]
    vehicles: dict[str, VehicleView]

    @property
    def flying(self) -> int:
        return sum(1 for v in self.vehicles.values() if v.flying)

    def to_json(self) -> dict[str, Any]:
        """The shape of ``plumeswarm status --json`` (a public surface, locked by a test)."""
        nodes = []
        for name in sorted(self.alive | set(self.health)):
            h = self.health.get(name)
            nodes.append(
                {
                    "name": name,
                    "alive": name in self.alive,
                    "role": h.role if h else None,
                    "state": str(h.state) if h else None,
                    "pid": h.pid if h else None,
                    "host": h.host if h else None,
                    "version": h.version if h else None,
                    "detail": h.detail if h else None,
                }
            )
        vehicles: dict[str, Any] = {}
        for vid, v in sorted(self.vehicles.items()):
            reading = v.reading
            vehicles[vid] = {
                "mode": str(v.status.mode) if v.status else None,
                "armed": v.status.armed if v.status else None,
                "position": list(v.position) if v.position is not None else None,
                "reading": reading.reported_g_m3 if reading is not None else None,
            }
        return {
            "sim_time": self.clock.sim_time_s if self.clock else None,
            "real_time_factor": self.clock.real_time_factor if self.clock else None,
            "nodes": nodes,
            "vehicles": vehicles,
        }


class BusView:
    """Latest clock, node health and per-vehicle data of one world."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self._lock = threading.Lock()
        self._changed = threading.Condition(self._lock)
        self._clock: bytes | None = None
        self._health: dict[str, bytes] = {}
        self._per_vehicle: dict[str, dict[str, bytes]] = {"state": {}, "status": {}, "reading": {}}
        self.presence = Presence(session, keys, on_change=self._on_presence)
        self._subs = [
            session.declare_subscriber(keys.clock(), self._on_clock),
            session.declare_subscriber(
                keys.all_node_health(), self._newest_by_name(keys.node_name_of, self._health)
            ),
        ]
        for kind, key in (
            ("state", keys.all_vehicle_states()),
            ("status", keys.all_vehicle_status()),
            ("reading", keys.all_vehicle_concentration()),
        ):
            table = self._per_vehicle[kind]
            handle = self._newest_by_name(keys.vehicle_id_of, table)
            self._subs.append(session.declare_subscriber(key, handle))

    # -- callbacks (Zenoh's threads): store, never decode --------------------
    def _notify(self) -> None:
        self._changed.notify_all()

    def _on_presence(self, name: str, alive: bool) -> None:
        with self._lock:
            self._notify()

    def _on_clock(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self._clock = sample.payload.to_bytes()
            self._notify()

    def _newest_by_name(
        self, name_of: Callable[[str], str], table: dict[str, bytes]
    ) -> Callable[[zenoh.Sample], None]:
        """A callback keeping in ``table`` the newest payload of each name ``name_of`` reads
        from a sample's key (a key it cannot read is ignored)."""

        def handle(sample: zenoh.Sample) -> None:
            try:
                name = name_of(str(sample.key_expr))
            except KeyNameError:
                return
            with self._lock:
                table[name] = sample.payload.to_bytes()
                self._notify()

        return handle

    # -- queries -------------------------------------------------------------
    @staticmethod
    def _decode(data: bytes | None, type_: type[M], what: str) -> M | None:
        return None if data is None else decode_or_none(data, type_, what, log)

    def snapshot(self) -> Snapshot:
        with self._lock:
            clock_raw = self._clock
            health_raw = dict(self._health)
            raw = {k: dict(v) for k, v in self._per_vehicle.items()}
        health = {
            n: h
            for n, data in health_raw.items()
            if (h := self._decode(data, NodeHealth, f"health of {n}")) is not None
        }
        ids = set().union(*(set(t) for t in raw.values()))
        vehicles = {
            vid: VehicleView(
                vid,
                self._decode(raw["state"].get(vid), VehicleState, f"state of {vid}"),
                self._decode(raw["status"].get(vid), VehicleStatus, f"status of {vid}"),
                self._decode(raw["reading"].get(vid), ConcentrationReading, f"reading of {vid}"),
            )
            for vid in ids
        }
        return Snapshot(
            clock=self._decode(clock_raw, Clock, "clock"),
            alive=self.presence.alive,
            health=health,
            vehicles=vehicles,
        )

    def wait_changed(self, timeout_s: float) -> None:
        """Block until anything new arrives or ``timeout_s`` passes."""
        with self._lock:
            self._changed.wait(timeout_s)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()
        self.presence.close()


def status_line(snap: Snapshot, expected_vehicles: int | None = None) -> str:
    """One line: sim time, real-time factor, vehicles flying, last readings."""
    clock = snap.clock
    t = f"t={clock.sim_time_s:8.2f}s rtf={clock.real_time_factor:5.2f}x" if clock else "t=--"
    total = expected_vehicles if expected_vehicles is not None else len(snap.vehicles)
    parts = [t, f"flying {snap.flying}/{total}", f"nodes {len(snap.alive)}"]
    readings = []
    for vid, v in sorted(snap.vehicles.items()):
        r = v.reading
        if r is not None:
            value = "n/a" if r.reported_g_m3 is None else f"{r.reported_g_m3:.3f}"
            readings.append(f"{vid}={value}")
    if readings:
        parts.append("g/m3 " + " ".join(readings))
    return " | ".join(parts)
