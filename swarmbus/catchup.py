"""Putting again what subscribers cut off with the router missed (docs/deploy.md, "When the
router dies").

Where the nodes reach each other only through the router (every node a client), what the router
held when it was killed is lost (a state or a reading queued for a subscriber), and so is what a
publisher puts before its subscribers are back on the new router. A publisher that keeps its
recent samples puts them again when a subscriber *matches it again* (Zenoh's matching status
goes from none to some) while the router is away or shortly after it came back; subscribers keep
one sample per (vehicle, tick) or (vehicle, sim time), so a sample they already had is a
duplicate with the same bytes. Outside a router outage nothing is put again: a subscriber that
joins a running world starts from what is published from then on, as before.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

import zenoh

from swarmbus.keys import Keys

ROUTER = "router"  # the router's node name (its token: node/router/health)
# How long after the router's return a subscriber matching again still gets the kept samples:
# every session reconnects within about 1 s of the new router (connect/retry up to 1 s).
OUTAGE_AFTER_S = 10.0


class RouterOutage:
    """Whether the router is away, or came back less than ``after_s`` ago (thread-safe)."""

    def __init__(
        self, clock: Callable[[], float] = time.monotonic, after_s: float = OUTAGE_AFTER_S
    ) -> None:
        self._clock = clock
        self._after_s = after_s
        self._lock = threading.Lock()
        self._away = False
        self._until = -1.0  # the outage's end, once the router is back

    def router(self, alive: bool) -> None:
        """The router's token came (``alive``) or went."""
        with self._lock:
            if alive and self._away:
                self._until = self._clock() + self._after_s
            self._away = not alive

    def on(self) -> bool:
        with self._lock:
            return self._away or self._clock() < self._until


def watch_router(session: zenoh.Session, keys: Keys, outage: RouterOutage) -> Any:
    """A liveliness subscriber that tells ``outage`` the router's comings and goings (the
    caller undeclares it)."""

    def on_token(sample: zenoh.Sample) -> None:
        outage.router(sample.kind == zenoh.SampleKind.PUT)

    # With the history: a client learns of the token's departure (its link to the router
    # broke) only if it knew the token was there.
    return session.liveliness().declare_subscriber(keys.node_health(ROUTER), on_token, history=True)


class Matching:
    """A publisher's matching status (kept up to date by a listener), and whether a subscriber
    matched it again (none, then some) since :meth:`again` was last asked."""

    def __init__(self, pub: zenoh.Publisher) -> None:
        self.matching = False
        self._again = False
        self._listener = pub.declare_matching_listener(self._on_matching)
        status: Any = pub.matching_status  # a MatchingStatus (the stub says bool)
        self.matching = bool(status.matching)

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        if status.matching and not self.matching:
            self._again = True
        self.matching = status.matching

    def again(self) -> bool:
        again, self._again = self._again, False
        return again

    def close(self) -> None:
        self._listener.undeclare()


class CatchUpPublisher:
    """A publisher that keeps its last ``depth`` payloads and puts them again when a subscriber
    matched it again during a router outage (:meth:`catch_up`, from the thread that puts)."""

    def __init__(self, session: zenoh.Session, key: str, depth: int) -> None:
        self.key = key
        self._pub = session.declare_publisher(key)
        self._kept: deque[bytes] = deque(maxlen=depth)
        self._matching = Matching(self._pub)

    @property
    def matching(self) -> bool:
        return self._matching.matching

    def put(self, payload: bytes) -> None:
        self._kept.append(payload)
        self._pub.put(payload)

    def catch_up(self, outage: RouterOutage) -> int:
        """Put the kept payloads again if a subscriber matched again during an outage; how
        many were put."""
        if not (self._matching.again() and outage.on()):
            return 0
        for payload in self._kept:
            self._pub.put(payload)
        return len(self._kept)

    def close(self) -> None:
        self._matching.close()
        self._pub.undeclare()
