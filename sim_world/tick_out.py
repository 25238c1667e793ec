"""Putting ticks on the bus: ``sim/tick``, ``sim/sensor`` for the sensor ticks, each state on
``vehicle/<id>/state`` while someone listens, and the re-sends (held ticks, backfill).

See docs/physics.md, "Lockstep" (rule 3) and "Restarts: the clock waits".
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Iterable, Sequence

import zenoh

from swarmbus.catchup import Matching, RouterOutage
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import VehicleState

log = logging.getLogger(__name__)

# The ticks whose states are kept to be put again for a subscriber back after a router outage
# (swarmbus.catchup): those the dead router held, and those published before the subscriber
# was back (the clock goes on once the participants are back: up to 190 ticks measured).
CATCH_UP_TICKS = 256  # kept at any time
CATCH_UP_OUTAGE_TICKS = 4096  # kept while an outage lasts


class TickOutput:
    """The current tick's bytes and states, and the publishers they go out on."""

    def __init__(
        self, session: zenoh.Session, keys: Keys, vehicle_ids: Sequence[str], sensor_period: int
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
        self._kept: deque[tuple[int, list[VehicleState]]] = deque(maxlen=CATCH_UP_OUTAGE_TICKS)

    def set(self, tick: int, payload: bytes, states: list[VehicleState]) -> None:
        """Tick ``tick`` (``payload``, its ``states``) is the current one."""
        self.tick = tick
        self.payload = payload
        self._states = states
        self._kept.append((tick, states))

    def catch_up(self, outage: RouterOutage) -> None:
        """Put the kept ticks' states again on each ``vehicle/<id>/state`` that a subscriber
        matched again during a router outage (it may have missed any of them); outside an
        outage keep the last CATCH_UP_TICKS only."""
        if not outage.on():
            while len(self._kept) > CATCH_UP_TICKS:
                self._kept.popleft()
        for i, pub in enumerate(self._state_pubs):
            if not (pub.matching_again() and outage.on()):
                continue
            for _, states in self._kept:
                pub.put(encode(states[i]))
            log.info(
                "tick %d: %s matched again after the router left: re-sent the states of "
                "ticks %d..%d",
                self.tick,
                pub.key,
                self._kept[0][0],
                self._kept[-1][0],
            )

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
        ``sim/backfill/<key>`` for a new recorder."""
        for entries in ticks:
            for key, payload in entries:
                self._session.put(self._keys.backfill_of(key), payload)

    def close(self) -> None:
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
