"""The Swarm client's view of the radio: what each talking vehicle's behaviour published
(``vehicle/<id>/radio``, one ``RadioBatch`` a tick), kept per vehicle as :class:`RadioSent`
messages that decode to the type the caller names. ``Swarm.radio``, ``Swarm.wait_radio``,
``Swarm.fetch_radio`` and ``Swarm.radio_links`` read it; see docs/agents.md ("Reading the
radio").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TypeVar, overload

import msgspec

from agents.peer_link import message_type
from agents.swarm_clients import SwarmError
from swarmbus.messages import RadioBatch
from swarmbus.radio import RadioError

S = TypeVar("S", bound=msgspec.Struct)

#: How many ticks of each vehicle's radio batches a client keeps (about 8.5 s at 120 Hz).
RADIO_KEPT_TICKS = 1024


class RadioReadError(SwarmError, ValueError):
    """A radio message that does not decode to the type asked for, or whose type (its
    ``module:QualName``) cannot be imported here."""


class RadioUnavailable(SwarmError, LookupError):
    """Nothing answered a query for a vehicle's kept radio batches (its behaviour does not
    talk, or its autopilot is not running)."""


@dataclass(frozen=True)
class RadioSent:
    """One message a vehicle's behaviour published (``ctx.mailbox.publish``) in its step of
    ``tick``: its place among that tick's messages (``index``, from 2: the radio's message
    index), its type (``kind``, ``module:QualName``) and its msgpack bytes (``payload``)."""

    sender: str
    tick: int
    index: int
    kind: str
    payload: bytes

    def is_a(self, type_: type[msgspec.Struct]) -> bool:
        """Whether the sender published an instance of ``type_`` (same ``module:QualName``)."""
        return self.kind == kind_of(type_)

    @overload
    def decode(self) -> msgspec.Struct: ...
    @overload
    def decode(self, type_: type[S]) -> S: ...
    def decode(self, type_: type[S] | None = None) -> S | msgspec.Struct:
        """The message as ``type_`` (any ``msgspec.Struct`` of the same fields), or, without
        it, as the type its ``kind`` names (imported); :class:`RadioReadError` if it is not."""
        target: type[msgspec.Struct]
        if type_ is None:
            try:
                target = message_type(self.kind)
            except RadioError as exc:
                raise RadioReadError(f"{self._where()}: {exc}") from None
        else:
            target = type_
        try:
            return msgspec.msgpack.decode(self.payload, type=target)
        except msgspec.DecodeError as exc:
            raise RadioReadError(
                f"{self._where()} ({self.kind}) is not a {target.__qualname__}: {exc}"
            ) from None

    def _where(self) -> str:
        return f"radio message {self.index} of {self.sender} at tick {self.tick}"


def kind_of(type_: type[msgspec.Struct]) -> str:
    """The ``kind`` (``module:QualName``) a message of ``type_`` travels with."""
    return f"{type_.__module__}:{type_.__qualname__}"


class RadioKept:
    """Each vehicle's last radio batches (at most ``ticks`` a vehicle), by tick, oldest first;
    the caller holds the lock around every call."""

    def __init__(self, ticks: int = RADIO_KEPT_TICKS) -> None:
        if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < 1:
            raise ValueError(f"radio_kept_ticks must be an integer >= 1, got {ticks!r}")
        self.ticks = ticks
        self._by_vehicle: dict[str, dict[int, list[RadioSent]]] = {}

    def add(self, batch: RadioBatch) -> list[RadioSent] | None:
        """Keep ``batch``; its messages, or None when it was kept already or is older than
        everything a full history keeps."""
        kept = self._by_vehicle.setdefault(batch.sender, {})
        if batch.tick in kept:
            return None
        last = next(reversed(kept), None)
        if len(kept) >= self.ticks and batch.tick < next(iter(kept)):
            return None
        sent = [
            RadioSent(batch.sender, batch.tick, m.index, m.kind, m.payload)
            for m in sorted(batch.messages, key=lambda m: m.index)
        ]
        kept[batch.tick] = sent
        if last is not None and batch.tick < last:  # a late one (a query's answer): re-order
            ordered = dict(sorted(kept.items()))
            kept.clear()
            kept.update(ordered)
        while len(kept) > self.ticks:
            del kept[next(iter(kept))]
        return sent

    def messages(self, vehicle_id: str, since_tick: int, kind: str | None) -> list[RadioSent]:
        kept = self._by_vehicle.get(vehicle_id, {})
        return [
            m
            for tick, sent in kept.items()
            if tick > since_tick
            for m in sent
            if kind is None or m.kind == kind
        ]

    def last_tick(self, vehicle_id: str) -> int | None:
        kept = self._by_vehicle.get(vehicle_id)
        return next(reversed(kept)) if kept else None
