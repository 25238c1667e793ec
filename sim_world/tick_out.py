"""Putting ticks on the bus: ``sim/tick``, ``sim/sensor`` for the sensor ticks, each state on
``vehicle/<id>/state`` while someone listens, and the re-sends (held ticks, backfill).

See docs/physics.md, "Lockstep" (rule 3) and "Restarts: the clock waits".
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Iterator, Sequence

import zenoh

from swarmbus.catchup import Kept, Matching, Put, Resender, RouterOutage
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import VehicleState
from swarmbus.views import TickView

log = logging.getLogger(__name__)

# The ticks whose states are kept to be put again for a subscriber back after a router outage
# (swarmbus.catchup): those the dead router held, and those published before the subscriber
# was back (the clock goes on once the participants are back: up to 190 ticks measured).
CATCH_UP_TICKS = 256  # kept at any time
CATCH_UP_OUTAGE_TICKS = 4096  # kept while an outage lasts
# ... and at most this many bytes of them (each tick's encoded SimTick, ~340 B a vehicle): at
# 128 vehicles about 1 500 ticks (6 s of a 240 Hz world), at 3 every one of the 4096.
CATCH_UP_MAX_BYTES = 64 * 1024 * 1024


class TickOutput:
    """The current tick's bytes and states, and the publishers they go out on."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        vehicle_ids: Sequence[str],
        sensor_period: int,
        max_kept_bytes: int = CATCH_UP_MAX_BYTES,
    ) -> None:
        self._session = session
        self._keys = keys
        self._sensor_period = sensor_period
        self._tick_pub = session.declare_publisher(keys.tick())
        self._sensor_pub = session.declare_publisher(keys.sensor_tick())
        self._state_pubs = [_StatePublisher(session, keys.vehicle_state(v)) for v in vehicle_ids]
        self.tick = 0
        self.payload = b""  # the current tick's SimTick, encoded
        self._states: list[VehicleState] = []
        self.states_sent = 0  # per-vehicle state puts (health detail)
        # The ticks kept for a catch-up: (tick, its SimTick bytes, which hold every state)
        self._kept: Kept[tuple[int, bytes]] = Kept(CATCH_UP_OUTAGE_TICKS, max_kept_bytes)
        self.resender = Resender("physics-catch-up")  # the re-sends, off the tick thread

    def set(self, tick: int, payload: bytes, states: list[VehicleState]) -> None:
        """Tick ``tick`` (``payload``, its ``states``) is the current one."""
        self.tick = tick
        self.payload = payload
        self._states = states
        self._kept.append((tick, payload), len(payload))

    @property
    def kept_bytes(self) -> int:
        """The bytes kept for a catch-up (at most ``max_kept_bytes``)."""
        return self._kept.nbytes

    def catch_up(self, outage: RouterOutage) -> None:
        """Put the kept ticks' states again on each ``vehicle/<id>/state`` that a subscriber
        matched again during a router outage (it may have missed any of them), on the
        resender's worker at its bounded rate; outside an outage keep the last CATCH_UP_TICKS
        only."""
        on = outage.on()
        if not on:
            self._kept.trim(CATCH_UP_TICKS)
        again = [i for i, pub in enumerate(self._state_pubs) if pub.matching_again() and on]
        if not again or not self._kept:
            return
        kept = self._kept.items()
        keys = ", ".join(self._state_pubs[i].key for i in again[:3])
        more = f" and {len(again) - 3} more" if len(again) > 3 else ""
        self.resender.submit(
            self._resends(kept, again),
            f"tick {self.tick}: {keys}{more} matched again after the router left: re-sent the "
            f"states of ticks {kept[0][0]}..{kept[-1][0]}",
        )

    def _resends(self, kept: list[tuple[int, bytes]], indices: list[int]) -> Iterator[Put]:
        """The puts of a catch-up: each kept tick decoded once (on the resender's worker), the
        states of ``indices`` put with the bytes they have in the tick (``encode(state)``)."""
        for tick, payload in kept:
            try:
                states = decode(payload, TickView).states
            except MessageError as exc:
                log.warning("catch-up: tick %d kept undecodable: %s", tick, exc)
                continue
            for i in indices:
                yield self._state_pubs[i].put, bytes(states[i])

    def put_tick(self) -> None:
        """The current tick on ``sim/tick``, and on ``sim/sensor`` if it is a sensor tick."""
        self._tick_pub.put(self.payload)
        if self.tick % self._sensor_period == 0:
            self._sensor_pub.put(self.payload)

    def put_states(self) -> list[tuple[str, bytes]]:
        """The current tick's states on ``vehicle/<id>/state`` (to those who listen); returns
        the ``(key, payload)`` of each state sent."""
        sent = []
        for pub, state in zip(self._state_pubs, self._states, strict=True):
            if pub.matching:  # nobody listens: the state is in the tick already
                payload = encode(state)
                pub.put(payload)
                sent.append((pub.key, payload))
                self.states_sent += 1
        return sent

    def backfill(self, ticks: Iterable[list[tuple[str, bytes]]]) -> None:
        """Re-send ``ticks`` (each a tick's and its states' key and payload) on
        ``sim/backfill/<key>`` for a new recorder. Blocking, not dropping, when the link's
        queue is full: the clock is held meanwhile, and a burst of 256 ticks dropped its
        tail under load."""
        block = zenoh.CongestionControl.BLOCK
        for entries in ticks:
            for key, payload in entries:
                self._session.put(self._keys.backfill_of(key), payload, congestion_control=block)

    def close(self) -> None:
        self.resender.close()
        for pub in self._state_pubs:
            pub.close()


class _StatePublisher:
    """A ``vehicle/<id>/state`` publisher that knows whether anyone subscribes (Zenoh's
    matching status, kept up to date by a listener): the physics skips encoding and putting a
    state nobody would receive. A subscriber declared later is matched before a put could
    reach it anyway (both follow the same subscription declarations), so it misses nothing."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.key = key
        self._pub = session.declare_publisher(key)
        self._matching = Matching(self._pub)

    @property
    def matching(self) -> bool:
        return self._matching.matching

    def matching_again(self) -> bool:
        """Whether a subscriber matched again (none, then some) since last asked."""
        return self._matching.again()

    def put(self, payload: bytes) -> None:
        self._pub.put(payload)

    def close(self) -> None:
        self._matching.close()
        self._pub.undeclare()
