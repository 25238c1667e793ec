"""What a vehicle's behaviour learns of its peers, carried over the scenario's radio.

:class:`PeerLink` is the radio (:class:`swarmbus.radio.Radio`, the scenario's ``[radio]``)
applied to a runner's traffic between vehicles, the same in the kinematic benchmark and the
fused runner:

- **peer states** (the ``peers`` a behaviour's ``step`` gets): each vehicle's state of tick
  ``t`` is one message (index :data:`STATE_INDEX`) to every other vehicle; a receiver's peers
  are the latest state it has received from each peer (in scenario order; a peer it has never
  heard from is left out);
- **peer readings** (``ConcentrationReading.peers``): each vehicle's sample of sensor tick
  ``t`` (its position and the field's value there) is one message (index
  :data:`READING_INDEX`); a receiver's next own reading carries those that have arrived;
- **behaviour messages**: a behaviour publishes a small typed message
  (a ``msgspec.Struct``, at most ``[radio] max_message_bytes`` encoded) with
  ``ctx.mailbox.publish(message)`` during its step of tick ``t``; it goes out with that step's
  answer, one message each (index :data:`MESSAGE_INDEX` + its place among the sender's
  messages of the tick) to every other vehicle, and is in the receivers' ``mailbox.inbox``
  (:class:`Received`) at their step of tick ``t + 1 + latency_ticks``.

A message of tick ``t`` arrives at tick ``t + latency_ticks`` if the radio delivers it (range
at the send tick, loss). With the default, perfect radio a runner passes peers as it always
has and only routes behaviour messages (next tick, to everyone).
"""

from __future__ import annotations

import functools
import heapq
import importlib
from collections.abc import Sequence
from dataclasses import dataclass

import msgspec

from swarmbus.messages import (
    ConcentrationReading,
    LinkStatus,
    PeerReading,
    RadioMessage,
    VehicleState,
)
from swarmbus.radio import Radio, RadioError
from swarmbus.scenario import Scenario

STATE_INDEX = 0
READING_INDEX = 1
MESSAGE_INDEX = 2

__all__ = [
    "MESSAGE_INDEX",
    "READING_INDEX",
    "STATE_INDEX",
    "LinkCount",
    "Mailbox",
    "PeerLink",
    "RadioError",
    "Received",
]


@dataclass(frozen=True)
class Received:
    """A peer's message as it reached this vehicle: who sent it, in which tick's step."""

    sender: str
    sent_tick: int
    message: msgspec.Struct


class Mailbox:
    """A behaviour's end of the radio (``BehaviorContext.mailbox``): :meth:`publish` in a
    step, :attr:`inbox` (what arrived for this step) read in it."""

    def __init__(self, vehicle_id: str, radio: Radio) -> None:
        self.vehicle_id = vehicle_id
        self.radio = radio
        self.inbox: list[Received] = []
        self.outbox: list[msgspec.Struct] = []

    def publish(self, message: msgspec.Struct) -> None:
        """Send ``message`` to every peer the radio reaches; :class:`RadioError` when it is
        larger than ``[radio] max_message_bytes`` encoded (msgpack)."""
        if not isinstance(message, msgspec.Struct):
            raise RadioError(
                f"radio: a message must be a msgspec.Struct, not {type(message).__name__}"
            )
        self.radio.check_size(msgspec.msgpack.encode(message))
        self.outbox.append(message)


@dataclass
class LinkCount:
    """What one link (sender → receiver) carried: messages delivered and dropped."""

    delivered: int = 0
    dropped: int = 0


class PeerLink:
    """The radio between one runner's vehicles (see the module's docstring)."""

    def __init__(self, scenario: Scenario) -> None:
        self.radio = Radio(scenario.radio, scenario.world.seed)
        self.ids = [v.id for v in scenario.vehicles]
        self.mailboxes = {vid: Mailbox(vid, self.radio) for vid in self.ids}
        self.counts: dict[tuple[str, str], LinkCount] = {}
        # (arrival tick, order, receiver, kind, sender, sent tick, payload)
        self._queue: list[tuple[int, int, str, int, str, int, object]] = []
        self._order = 0
        self._known: dict[str, dict[str, VehicleState]] = {vid: {} for vid in self.ids}
        self._arrived_readings: dict[str, dict[str, PeerReading]] = {vid: {} for vid in self.ids}

    @property
    def perfect(self) -> bool:
        return self.radio.perfect

    def _send(
        self,
        tick: int,
        index: int,
        kind: int,
        sender: VehicleState,
        receivers: Sequence[VehicleState],
        payload: object,
        arrival: int,
    ) -> None:
        for r in receivers:
            if r.vehicle_id == sender.vehicle_id:
                continue
            link = (sender.vehicle_id, r.vehicle_id)
            count = self.counts.setdefault(link, LinkCount())
            if self.radio.delivers(tick, *link, index, sender.position_enu_m, r.position_enu_m):
                count.delivered += 1
                item = (arrival, self._order, r.vehicle_id, kind, sender.vehicle_id, tick)
                self._order += 1
                heapq.heappush(self._queue, (*item, payload))
            else:
                count.dropped += 1

    def _deliver(self, tick: int) -> None:
        while self._queue and self._queue[0][0] <= tick:
            _, _, receiver, kind, sender, sent, payload = heapq.heappop(self._queue)
            if kind == STATE_INDEX:
                assert isinstance(payload, VehicleState)
                self._known[receiver][sender] = payload
            elif kind == READING_INDEX:
                assert isinstance(payload, PeerReading)
                self._arrived_readings[receiver][sender] = payload
            else:
                assert isinstance(payload, msgspec.Struct)
                self.mailboxes[receiver].inbox.append(Received(sender, sent, payload))

    def peers(self, tick: int, states: Sequence[VehicleState]) -> list[list[VehicleState]]:
        """Each vehicle's peers at ``tick`` (``states``: every vehicle's, in scenario order),
        after the states of this tick have been sent."""
        if self.perfect:
            return [list(states[:i]) + list(states[i + 1 :]) for i in range(len(states))]
        arrival = self.radio.arrival_tick(tick)
        for s in states:
            self._send(tick, STATE_INDEX, STATE_INDEX, s, states, s, arrival)
        self._deliver(tick)
        return [
            [known[p] for p in self.ids if p in known]
            for known in (self._known[s.vehicle_id] for s in states)
        ]

    def readings(
        self, tick: int, states: Sequence[VehicleState], readings: Sequence[ConcentrationReading]
    ) -> list[ConcentrationReading]:
        """``readings`` (this sensor tick's, one per vehicle sampled, their peers attached as
        the sensor makes them) with their peers' samples replaced by those the radio has
        brought by ``tick``."""
        if self.perfect:
            return list(readings)
        arrival = self.radio.arrival_tick(tick)
        by_id = {s.vehicle_id: s for s in states}
        for r in readings:
            sample = PeerReading(
                vehicle_id=r.vehicle_id,
                position_enu_m=r.position_enu_m,
                true_g_m3=r.true_g_m3 if r.true_g_m3 is not None else 0.0,
            )
            if r.true_g_m3 is not None:
                self._send(tick, READING_INDEX, READING_INDEX, by_id[r.vehicle_id], states, sample,
                           arrival)  # fmt: skip
        self._deliver(tick)
        out = []
        for r in readings:
            arrived = self._arrived_readings[r.vehicle_id]
            peers = [arrived[p] for p in self.ids if p in arrived]
            self._arrived_readings[r.vehicle_id] = {}
            out.append(msgspec.structs.replace(r, peers=peers))
        return out

    def before_step(self, tick: int) -> None:
        """Fill every mailbox's inbox with the messages that arrive by ``tick``."""
        for box in self.mailboxes.values():
            box.inbox = []
        if self._queue:
            self._deliver(tick)

    def after_step(self, tick: int, states: Sequence[VehicleState]) -> None:
        """Send what the behaviours published in their steps of ``tick``."""
        arrival = self.radio.arrival_tick(tick + 1)
        by_id: dict[str, VehicleState] = {}
        for vid, box in self.mailboxes.items():
            if not box.outbox:
                continue
            if not by_id:
                by_id = {s.vehicle_id: s for s in states}
            for n, message in enumerate(box.outbox):
                self._send(tick, MESSAGE_INDEX + n, MESSAGE_INDEX, by_id[vid], states, message,
                           arrival)  # fmt: skip
            box.outbox = []

    # ------------------------------------------------------------------ across processes
    def outbox(self, vehicle_id: str) -> list[RadioMessage]:
        """What ``vehicle_id``'s behaviour published in its last step, encoded for the bus."""
        return [
            RadioMessage(index=MESSAGE_INDEX + n, kind=message_kind(m), payload=_encode(m))
            for n, m in enumerate(self.mailboxes[vehicle_id].outbox)
        ]

    def put_outbox(self, vehicle_id: str, messages: Sequence[RadioMessage]) -> None:
        """What another process's ``vehicle_id`` published in a step, as if published here
        (sent on :meth:`after_step`); :class:`RadioError` for a message of an unknown type."""
        self.mailboxes[vehicle_id].outbox = [
            msgspec.msgpack.decode(m.payload, type=message_type(m.kind))
            for m in sorted(messages, key=lambda m: m.index)
        ]

    def link_status(self, receiver: str) -> list[LinkStatus]:
        """What the links into ``receiver`` delivered and dropped, in scenario order."""
        return [
            LinkStatus(sender=sender, delivered=c.delivered, dropped=c.dropped)
            for sender in self.ids
            if (c := self.counts.get((sender, receiver))) is not None
        ]

    def snapshot(self) -> bytes:
        """The link's state (messages in flight, what each vehicle knows, the counts and the
        outboxes) for :meth:`restore`."""
        queue = [
            _Queued(arrival, order, receiver, kind, sender, sent, message_kind(p), _encode(p))
            for arrival, order, receiver, kind, sender, sent, p in self._queue
        ]
        snap = _LinkSnapshot(
            order=self._order,
            queue=queue,
            known={r: list(k.values()) for r, k in self._known.items()},
            readings={r: list(k.values()) for r, k in self._arrived_readings.items()},
            counts=[(s, r, c.delivered, c.dropped) for (s, r), c in self.counts.items()],
            outboxes={vid: self.outbox(vid) for vid in self.ids},
        )
        return msgspec.msgpack.encode(snap)

    def restore(self, data: bytes) -> None:
        """Back to a :meth:`snapshot`."""
        snap = msgspec.msgpack.decode(data, type=_LinkSnapshot)
        self._order = snap.order
        self._queue = [
            (q.arrival, q.order, q.receiver, q.kind, q.sender, q.sent,
             msgspec.msgpack.decode(q.payload, type=message_type(q.type)))
            for q in snap.queue
        ]  # fmt: skip
        heapq.heapify(self._queue)
        self._known = {vid: {} for vid in self.ids}
        for r, states in snap.known.items():
            self._known[r] = {s.vehicle_id: s for s in states}
        self._arrived_readings = {vid: {} for vid in self.ids}
        for r, readings in snap.readings.items():
            self._arrived_readings[r] = {p.vehicle_id: p for p in readings}
        self.counts = {(s, r): LinkCount(d, x) for s, r, d, x in snap.counts}
        for vid in self.ids:
            self.put_outbox(vid, snap.outboxes.get(vid, []))
            self.mailboxes[vid].inbox = []


class _Queued(msgspec.Struct, frozen=True, array_like=True):
    arrival: int
    order: int
    receiver: str
    kind: int
    sender: str
    sent: int
    type: str
    payload: bytes


class _LinkSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    order: int
    queue: list[_Queued]
    known: dict[str, list[VehicleState]]
    readings: dict[str, list[PeerReading]]
    counts: list[tuple[str, str, int, int]]
    outboxes: dict[str, list[RadioMessage]]


_encoder = msgspec.msgpack.Encoder()


def _encode(message: object) -> bytes:
    return _encoder.encode(message)


def message_kind(message: object) -> str:
    """The ``module:QualName`` of a message's type (how a receiver decodes it)."""
    cls = type(message)
    return f"{cls.__module__}:{cls.__qualname__}"


@functools.cache
def message_type(kind: str) -> type[msgspec.Struct]:
    """The ``msgspec.Struct`` type a :func:`message_kind` names; :class:`RadioError` if none."""
    module, _, name = kind.partition(":")
    try:
        found: object = importlib.import_module(module)
        for part in name.split("."):
            found = getattr(found, part)
    except (ImportError, AttributeError, ValueError) as exc:
        raise RadioError(f"radio: message type {kind!r} not found: {exc}") from None
    if not (isinstance(found, type) and issubclass(found, msgspec.Struct)):
        raise RadioError(f"radio: message type {kind!r} is not a msgspec.Struct")
    return found
