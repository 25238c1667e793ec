"""What the autopilot process's loop takes in: ticks decoded as far as they are used, and the
events of its inbox in arrival order (docs/architecture.md, "How a tick flows")."""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Generic, TypeVar

import msgspec

from swarmbus.codec import MessageError, decode
from swarmbus.messages import SimTick, VehicleState
from swarmbus.views import StateHead, TickView, state_head_decoder

# Longest wait for an event: the stop signal is seen this often (a signal's handler runs only
# when the main thread wakes).
EVENT_POLL_S = 0.25


class Tick:
    """One tick, decoded as far as it is used: a vehicle's own state always, every vehicle's
    position on a sensor tick, the peers' full states only for a behaviour (once per process)."""

    def __init__(self, view: TickView) -> None:
        self.tick = view.tick
        self.sim_time_s = view.sim_time_s
        self.raw = view.states
        self.plume_queried = view.plume_queried
        self.plume_values = view.plume_values
        self._heads: list[StateHead] | None = None
        self._states: list[VehicleState] | None = None

    @classmethod
    def decode(cls, data: bytes) -> Tick:
        return cls(decode(data, TickView))

    def state_of(self, vehicle_id: str, hint: int) -> tuple[int, VehicleState] | None:
        """``vehicle_id``'s index and state: at ``hint`` (its place in the scenario, where the
        physics puts it) or, should the list differ, wherever its head says."""
        if 0 <= hint < len(self.raw):
            state = decode(self.raw[hint], VehicleState)
            if state.vehicle_id == vehicle_id:
                return hint, state
        for k, head in enumerate(self.heads()):
            if head.vehicle_id == vehicle_id:
                return k, decode(self.raw[k], VehicleState)
        return None

    def heads(self) -> list[StateHead]:
        """Who is where in this tick."""
        if self._heads is None:
            try:
                self._heads = [state_head_decoder.decode(r) for r in self.raw]
            except (msgspec.ValidationError, msgspec.DecodeError) as exc:
                raise MessageError("SimTick", "states", str(exc)) from None
        return self._heads

    def states(self) -> list[VehicleState]:
        """Every vehicle's state (decoded once)."""
        if self._states is None:
            self._states = [decode(r, VehicleState) for r in self.raw]
        return self._states

    def peers_of(self, own: int) -> list[VehicleState]:
        states = self.states()
        return states[:own] + states[own + 1 :]


@dataclass
class PendingSensor:
    """A sensor tick whose plume values the node waits for."""

    tick: int
    sim_time_s: float
    states: list[StateHead]
    by_physics: bool  # the physics queried: the answer comes with a later tick (else: none)


# ---------------------------------------------------------------------- events
@dataclass(frozen=True, slots=True)
class TickArrived:
    """A ``sim/tick`` sample (still encoded)."""

    data: bytes


@dataclass(frozen=True, slots=True)
class Idle:
    """Nothing arrived for ``EVENT_POLL_S``."""


IDLE = Idle()
E = TypeVar("E")


class Inbox(Generic[E]):
    """The node's events (of type ``E``, some of them :class:`TickArrived`) in arrival order.
    Bus callbacks only :meth:`put` (on zenoh-python's callback thread: no node state, no
    blocking); the node's one loop takes them from :meth:`events`."""

    def __init__(self) -> None:
        self._queue: queue.SimpleQueue[E] = queue.SimpleQueue()

    def put(self, event: E) -> None:
        self._queue.put(event)

    def events(self, stop: threading.Event) -> Iterator[E | Idle]:
        """Every event in order, ``Idle`` after ``EVENT_POLL_S`` without one, until ``stop``.
        Of ticks that piled up only the newest is handed out (behind: only the latest counts)."""
        q = self._queue
        while not stop.is_set():
            try:
                arrived = [q.get(timeout=EVENT_POLL_S)]
            except queue.Empty:
                yield IDLE
                continue
            while not q.empty():
                arrived.append(q.get_nowait())
            ticks = [k for k, e in enumerate(arrived) if isinstance(e, TickArrived)]
            newest = _newest_tick(arrived, ticks)
            for k, event in enumerate(arrived):
                if k == newest or not isinstance(event, TickArrived):
                    yield event
            del arrived  # the events handed out must not outlive their handling (queries)


def _newest_tick(arrived: list[E], ticks: list[int]) -> int:
    """The index of the newest of the piled-up ticks that is a whole SimTick: a sample on
    ``sim/tick`` that is not (garbage, a stranger's put) must not push the real tick it arrived
    behind out of the pile, or the physics would wait for an answer that never comes. None
    decodes: the newest (the loop logs and ignores it). Piles are rare (a held tick re-sent,
    a realtime clock running ahead), so the whole decode costs little."""
    if len(ticks) < 2:
        return ticks[-1] if ticks else -1
    for k in reversed(ticks):
        event = arrived[k]
        assert isinstance(event, TickArrived)
        try:
            decode(event.data, SimTick)  # whole: a partial view lets a mangled tick through
        except MessageError:
            continue
        return k
    return ticks[-1]
