"""The radio between vehicles: which message from one vehicle reaches which other, and when.

One link model for every runner (the kinematic benchmark, the fused runner, the distributed
stack): each decision is a pure function of the scenario's ``[radio]`` section, the world seed
and (tick, sender, receiver, message index) — never of the order in which it is asked, nor of
who asks — so any process that holds the scenario decides the same delivery for the same
message.

- **Range** (``range_m``; 0: unlimited): a message reaches a receiver within ``range_m`` of its
  sender (horizontal and vertical, the two positions at the send tick), and no other.
- **Loss** (``loss``): each (tick, sender, receiver, index) is lost with probability ``loss``,
  independently: the draw is a uniform number made from a BLAKE2b hash of the seed and those
  four values (:func:`link_uniform`).
- **Latency** (``latency_ticks``): a message sent at tick ``t`` arrives at tick
  ``t + latency_ticks``.
- **Size** (``max_message_bytes``): the largest message, encoded, a behaviour may publish
  (default 255 bytes, MAVLink 2's largest payload); a larger one is refused at publication
  (:class:`RadioError`).

The default section is a perfect link: range unlimited, no loss, no latency.
"""

from __future__ import annotations

import hashlib
import math
import struct
from collections.abc import Sequence
from typing import Annotated

import msgspec

from swarmbus.errors import PlumeswarmError

#: MAVLink 2's largest payload: the default size limit of a behaviour's message.
DEFAULT_MAX_MESSAGE_BYTES = 255

_UNIT = 2.0**-53


class RadioError(PlumeswarmError, ValueError):
    """A message the radio cannot carry (larger than ``max_message_bytes``)."""


class RadioSpec(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """``[radio]``: the link between every two vehicles (the default: a perfect link)."""

    range_m: Annotated[
        float,
        msgspec.Meta(ge=0.0, le=1e9, description="Farthest distance a message reaches, m; 0: any."),
    ] = 0.0
    loss: Annotated[
        float,
        msgspec.Meta(ge=0.0, le=1.0, description="Probability that a message between two is lost."),
    ] = 0.0
    latency_ticks: Annotated[
        int,
        msgspec.Meta(ge=0, le=1_000_000, description="Control ticks a message takes to arrive."),
    ] = 0
    max_message_bytes: Annotated[
        int,
        msgspec.Meta(ge=1, le=1_000_000, description="Largest encoded message a vehicle may send."),
    ] = DEFAULT_MAX_MESSAGE_BYTES

    @property
    def perfect(self) -> bool:
        """Every message arrives, on the tick it is sent."""
        return self.range_m == 0.0 and self.loss == 0.0 and self.latency_ticks == 0


def link_uniform(seed: int, tick: int, sender: str, receiver: str, index: int) -> float:
    """A uniform number in [0, 1) that depends on these five values only."""
    h = hashlib.blake2b(digest_size=8, person=b"plumeswarm-link")
    h.update(struct.pack("<qqq", seed & (2**63 - 1), tick, index))
    h.update(sender.encode())
    h.update(b"\x00")
    h.update(receiver.encode())
    return (int.from_bytes(h.digest(), "little") >> 11) * _UNIT


class Radio:
    """The scenario's ``[radio]`` for one world seed: delivery decisions and arrival ticks."""

    def __init__(self, spec: RadioSpec, seed: int) -> None:
        self.spec = spec
        self.seed = seed

    @property
    def perfect(self) -> bool:
        return self.spec.perfect

    def in_range(self, sender_at: Sequence[float], receiver_at: Sequence[float]) -> bool:
        """Whether two positions (ENU metres) are within range of each other."""
        return self.spec.range_m == 0.0 or math.dist(sender_at, receiver_at) <= self.spec.range_m

    def delivers(
        self,
        tick: int,
        sender: str,
        receiver: str,
        index: int = 0,
        sender_at: Sequence[float] | None = None,
        receiver_at: Sequence[float] | None = None,
    ) -> bool:
        """Whether message ``index`` sent by ``sender`` at ``tick`` reaches ``receiver``
        (positions at the send tick, for the range; ``None``: in range)."""
        if (
            sender_at is not None
            and receiver_at is not None
            and not self.in_range(sender_at, receiver_at)
        ):
            return False
        loss = self.spec.loss
        if loss == 0.0:
            return True
        return link_uniform(self.seed, tick, sender, receiver, index) >= loss

    def arrival_tick(self, tick: int) -> int:
        """When a message sent at ``tick`` arrives."""
        return tick + self.spec.latency_ticks

    def check_size(self, encoded: bytes) -> None:
        """:class:`RadioError` when an encoded message is over the size limit."""
        limit = self.spec.max_message_bytes
        if len(encoded) > limit:
            raise RadioError(
                f"radio.max_message_bytes: a message of {len(encoded)} bytes is over the "
                f"limit of {limit} bytes"
            )
