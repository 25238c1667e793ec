"""What a fault test's subscribers keep of a lockstep flight, to compare two runs bit for bit:
every ``vehicle/<id>/state`` payload by vehicle and tick and every ``ConcentrationReading``
payload by vehicle and sim time (the first seen; a replayed tick or reading that differs is a
conflict), and each vehicle's latest status. :func:`save` and :func:`load` carry it out of a
process that flew in another network namespace."""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import msgspec
import zenoh

from plumeswarm.experiments.chaos import keep_state
from swarmbus.codec import decode
from swarmbus.messages import ConcentrationReading, VehicleState, VehicleStatus
from tests.support.procs import wait_until

T = TypeVar("T")


@dataclass
class Flown:
    vehicles: tuple[str, ...]  # those flying missions
    gate: str  # the scripted participant that starts them on a known tick
    control_hz: float = 120.0
    lock: threading.Lock = field(default_factory=threading.Lock)
    # every state payload by vehicle and tick (the first seen; a replay must repeat it)
    states: dict[str, dict[int, bytes]] = field(default_factory=dict)
    conflicts: list[tuple[str, int]] = field(default_factory=list)
    status: dict[str, VehicleStatus] = field(default_factory=dict)
    # every concentration reading payload by vehicle and sim time (the first seen)
    readings: dict[str, dict[float, bytes]] = field(default_factory=dict)

    def on_reading(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        r = decode(payload, ConcentrationReading)
        with self.lock:
            old = self.readings.setdefault(r.vehicle_id, {}).setdefault(r.sim_time_s, payload)
            if old != payload:
                self.conflicts.append((r.vehicle_id, -1))

    def on_state(self, sample: zenoh.Sample) -> None:
        with self.lock:
            keep_state(self.states, self.conflicts, sample.payload.to_bytes())

    def on_status(self, sample: zenoh.Sample) -> None:
        s = decode(sample.payload.to_bytes(), VehicleStatus)
        with self.lock:
            self.status[s.vehicle_id] = s

    def tend(self) -> None:
        """Called on every poll of :meth:`wait` (nothing here)."""

    def wait(self, predicate: Callable[[], T], timeout_s: float, what: str) -> T:
        """``wait_until`` of ``predicate`` under the lock, calling :meth:`tend` meanwhile."""

        def check() -> T:
            self.tend()
            with self.lock:
                return predicate()

        return wait_until(check, timeout_s, what, poll_s=0.05)

    def last_tick(self, vid: str) -> int:
        ticks = self.states.get(vid)
        return max(ticks) if ticks else -1

    def on_first_leg(self, vid: str, timeout_s: float) -> int:
        """Once ``vid`` flies its first mission leg: the last tick of it seen then, once its
        states have caught up with the status that says so (the two streams are separate
        subscriptions: under load the states seen lagged the physics by 200 ticks, still
        climbing)."""
        leg = self.wait(
            lambda: s if (s := self.status.get(vid)) is not None and s.mission_index >= 1 else None,
            timeout_s,
            f"{vid} on its first leg",
        )
        leg_tick = round(leg.sim_time_s * self.control_hz)
        self.wait(lambda: self.last_tick(vid) >= leg_tick, timeout_s, f"{vid}'s tick {leg_tick}")
        with self.lock:
            return self.last_tick(vid)

    def done(self) -> bool:
        """Every mission finished and every vehicle landed and disarmed (caller holds lock)."""
        return all(
            (s := self.status.get(v)) is not None
            and s.mission_finished
            and s.landed
            and not s.armed
            for v in self.vehicles
        )

    def z(self, vid: str, tick: int) -> float:
        return decode(self.states[vid][tick], VehicleState).position_enu_m[2]


class _Saved(msgspec.Struct):
    vehicles: list[str]
    gate: str
    control_hz: float
    states: dict[str, dict[int, bytes]]
    readings: dict[str, list[tuple[float, bytes]]]
    conflicts: list[tuple[str, int]]


def save(f: Flown, path: Path) -> None:
    """``f``'s states, readings and conflicts in ``path`` (msgpack; statuses are not kept)."""
    with f.lock:
        saved = _Saved(
            list(f.vehicles),
            f.gate,
            f.control_hz,
            f.states,
            {v: sorted(r.items()) for v, r in f.readings.items()},
            f.conflicts,
        )
        path.write_bytes(msgspec.msgpack.encode(saved))


def load(path: Path) -> Flown:
    s = msgspec.msgpack.decode(path.read_bytes(), type=_Saved)
    return Flown(
        tuple(s.vehicles),
        s.gate,
        s.control_hz,
        states=s.states,
        conflicts=list(s.conflicts),
        readings={v: dict(r) for v, r in s.readings.items()},
    )
