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

What is kept is bounded in bytes as well as in count (:class:`Kept`), and the samples are put
again by a worker thread at a bounded rate (:class:`Resender`): the thread that publishes (the
physics' tick loop, an autopilot's) only hands them over, so a router outage with many
vehicles does not stall it.
"""

from __future__ import annotations

import logging
import queue
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from typing import Any, Generic, TypeVar

import zenoh

from swarmbus.keys import Keys

log = logging.getLogger(__name__)

ROUTER = "router"  # the router's node name (its token: node/router/health)
# The puts per second a Resender makes at most: a re-send of 128 vehicles' 1 000 ticks takes
# about 6 s and leaves the processor to the tick loop (docs/reliability.md, "Bounded resources").
RESEND_RATE_PER_S = 20_000.0
_RESEND_BURST = 200  # puts between two looks at the clock
Put = tuple[Callable[[bytes], object], bytes]  # a put to make: the publisher's put, the payload
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


T = TypeVar("T")


class Kept(Generic[T]):
    """The last items kept, at most ``count`` of them and ``max_bytes`` of their sizes in all
    (the oldest go first; one item larger than ``max_bytes`` alone is kept alone). Not
    thread-safe: the thread that publishes keeps them."""

    def __init__(self, count: int, max_bytes: int) -> None:
        self.count = count
        self.max_bytes = max_bytes
        self._items: deque[tuple[int, T]] = deque()
        self.nbytes = 0

    def append(self, item: T, nbytes: int) -> None:
        self._items.append((nbytes, item))
        self.nbytes += nbytes
        self.trim(self.count)

    def trim(self, count: int) -> None:
        """Keep at most ``count`` items (and ``max_bytes``)."""
        items = self._items
        while len(items) > 1 and (len(items) > count or self.nbytes > self.max_bytes):
            self.nbytes -= items.popleft()[0]

    def items(self) -> list[T]:
        return [item for _, item in self._items]

    def __len__(self) -> int:
        return len(self._items)

    def __iter__(self) -> Iterator[T]:
        return (item for _, item in self._items)


class Resender:
    """A worker thread that makes the puts of a catch-up, at most ``rate_per_s`` puts a
    second, in the order the jobs came: the thread that publishes hands a job over
    (:meth:`submit`) and goes on. A job is an iterable of ``(put, payload)``, iterated on the
    worker (a generator may decode lazily there)."""

    def __init__(self, name: str, rate_per_s: float = RESEND_RATE_PER_S) -> None:
        self.rate_per_s = rate_per_s
        self._jobs: queue.SimpleQueue[tuple[Iterable[Put], str]] = queue.SimpleQueue()
        self._idle = threading.Condition()
        self._pending = 0
        self.puts = 0  # puts made so far
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, job: Iterable[Put], done: str = "") -> None:
        """Queue ``job``; ``done`` is logged (info) once its puts are made."""
        with self._idle:
            self._pending += 1
        self._jobs.put((job, done))

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until every job submitted is done; whether it is."""
        with self._idle:
            return self._idle.wait_for(lambda: self._pending == 0, timeout_s)

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                job, done = self._jobs.get(timeout=0.1)
            except queue.Empty:
                continue
            try:
                t0, n = time.monotonic(), 0
                for put, payload in job:
                    put(payload)
                    n += 1
                    if n % _RESEND_BURST == 0:
                        ahead = t0 + n / self.rate_per_s - time.monotonic()
                        if ahead > 0.0 and self._stop.wait(ahead):
                            break
                self.puts += n
                if done:
                    log.info("%s (%d puts in %.2f s)", done, n, time.monotonic() - t0)
            except Exception:  # a put on a closed session, a bad payload: the next job goes on
                log.exception("catch-up re-send failed")
            finally:
                with self._idle:
                    self._pending -= 1
                    self._idle.notify_all()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(2.0)


# What an autopilot keeps of its readings for a catch-up, in bytes (a reading is ~200 B).
CATCH_UP_MAX_BYTES = 4 * 1024 * 1024


class CatchUpPublisher:
    """A publisher that keeps its last ``depth`` payloads (at most ``max_bytes`` of them) and
    puts them again when a subscriber matched it again during a router outage
    (:meth:`catch_up`, from the thread that puts; the puts are made by ``resender``'s worker,
    or at once without one)."""

    def __init__(
        self,
        session: zenoh.Session,
        key: str,
        depth: int,
        resender: Resender | None = None,
        max_bytes: int = CATCH_UP_MAX_BYTES,
    ) -> None:
        self.key = key
        self._pub = session.declare_publisher(key)
        self._kept: Kept[bytes] = Kept(depth, max_bytes)
        self._matching = Matching(self._pub)
        self._resender = resender

    @property
    def matching(self) -> bool:
        return self._matching.matching

    @property
    def kept_bytes(self) -> int:
        return self._kept.nbytes

    def put(self, payload: bytes) -> None:
        self._kept.append(payload, len(payload))
        self._pub.put(payload)

    def catch_up(self, outage: RouterOutage) -> int:
        """Put the kept payloads again if a subscriber matched again during an outage; how
        many are put."""
        if not (self._matching.again() and outage.on()):
            return 0
        payloads = self._kept.items()
        if self._resender is None:
            for payload in payloads:
                self._pub.put(payload)
        else:
            self._resender.submit((self._pub.put, p) for p in payloads)
        return len(payloads)

    def close(self) -> None:
        self._matching.close()
        self._pub.undeclare()
