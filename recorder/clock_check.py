"""The recorder's check of the hosts' clocks.

Nothing in the simulation compares one host's wall clock with another's (its time is the
physics' tick; every timeout is measured on the local monotonic clock), but every sample
carries its publisher's Zenoh timestamp, a hybrid logical clock (HLC) time that the recording
keeps as ``publish_time``. Zenoh takes such a timestamp as it is when it is at most
:data:`CLOCK_BOUND_S` (its HLC's maximum delta, 500 ms unless ``UHLC_MAX_DELTA_MS`` says
otherwise) ahead of the receiver's clock; one
further ahead is replaced by the receiver's own (by the router's, when the sample came
through it), with a log line only if Zenoh's own logging is on. A publisher whose clock is
behind is never corrected.

:class:`ClockCheck` watches, on the recorder's Zenoh callback (a few samples per key per
second), what arrives: a sample stamped by this session or by a router although another node
published it (its publisher's clock was more than the bound ahead), and a publisher whose
timestamps stay more than the bound behind this host's clock when they arrive (the largest of
its last few publish − receive differences, so that transport and scheduling delays do not
count). Each is reported once, as one line naming the key, the publisher and the bound.
"""

from __future__ import annotations

import os
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping

import zenoh

from swarmbus.session import CLOCK_DELTA_VARIABLE

# Zenoh's HLC delta (uhlc's default of 500 ms; eclipse-zenoh 1.10): a sample stamped further
# ahead of the receiver's clock is re-stamped by the receiver. uhlc reads UHLC_MAX_DELTA_MS
# (milliseconds) from each process's environment (swarmbus.session checks it).
DEFAULT_CLOCK_BOUND_S = 0.5


def zenoh_clock_bound_s(environ: Mapping[str, str] = os.environ) -> float:
    """This process's Zenoh HLC delta in seconds: ``UHLC_MAX_DELTA_MS`` (whole milliseconds),
    else uhlc's default, 0.5 s."""
    raw = environ.get(CLOCK_DELTA_VARIABLE, "")
    if raw.isascii() and raw.isdigit():
        return int(raw) / 1000.0
    return DEFAULT_CLOCK_BOUND_S


CLOCK_BOUND_S = zenoh_clock_bound_s()


class ClockCheck:
    """Reports publishers whose clocks differ from this host's by more than ``bound_s``.

    ``own_keys(key)`` is True for the keys this session or a router publishes itself (their
    samples carry this session's or the router's id legitimately); ``report(key, detail)`` is
    called once per finding."""

    def __init__(
        self,
        session: zenoh.Session,
        own_keys: Callable[[str], bool],
        report: Callable[[str, str], None],
        bound_s: float = CLOCK_BOUND_S,
        period_s: float = 0.2,
        window: int = 10,
    ) -> None:
        self._session = session
        self._own_keys = own_keys
        self._report = report
        self._bound_ns = round(bound_s * 1e9)
        self._period_s = period_s
        self._window = window
        self._next: dict[str, float] = {}  # key → monotonic time of its next check
        self._offsets: dict[str, deque[int]] = {}  # publisher id → publish − receive (ns)
        self._warned: set[str] = set()  # publisher ids and re-stamped keys reported
        self._own_id = str(session.zid())
        self._stampers: set[str] = {self._own_id}
        self._stampers_at = -1e9
        self._lock = threading.Lock()

    def observe(self, key: str, sample: zenoh.Sample, receive_ns: int) -> None:
        """Check ``sample`` (received at ``receive_ns``, this host's wall clock) if its key is
        due; cheap otherwise."""
        now = time.monotonic()
        if now < self._next.get(key, 0.0):
            return
        self._next[key] = now + self._period_s
        stamp = sample.timestamp
        if stamp is None or self._own_keys(key):
            return
        publisher = str(stamp.get_id())
        offset_ns = int(stamp.get_time_as_ntp64().as_nanos()) - receive_ns
        with self._lock:
            if publisher in self._restampers(now):
                self._restamped(key, publisher)
            else:
                self._behind(key, publisher, offset_ns)

    def _restampers(self, now: float) -> set[str]:
        """This session's id and its routers' (refreshed every few seconds)."""
        if now - self._stampers_at > 5.0:
            self._stampers_at = now
            routers = {str(z) for z in self._session.info.routers_zid()}
            self._stampers = {self._own_id, *routers}
        return self._stampers

    def _restamped(self, key: str, stamper: str) -> None:
        if key in self._warned:
            return
        self._warned.add(key)
        by = "this host" if stamper == self._own_id else f"the router {stamper}"
        self._report(
            key,
            f"{key}: its publisher's clock is more than {self._bound_ns / 1e9:.1f} s ahead of "
            f"{by}'s, which re-stamped its samples (Zenoh); their recorded publish times are "
            f"{by}'s (check the hosts' clocks: chronyc tracking)",
        )

    def _behind(self, key: str, publisher: str, offset_ns: int) -> None:
        recent = self._offsets.setdefault(publisher, deque(maxlen=self._window))
        recent.append(offset_ns)
        if publisher in self._warned or len(recent) < self._window:
            return
        best = max(recent)  # the least delayed of the last few: the clocks' difference
        if best >= -self._bound_ns:
            return
        self._warned.add(publisher)
        self._report(
            key,
            f"{key}: its publisher's clock ({publisher}) is {-best / 1e9:.2f} s behind this "
            f"host's (more than {self._bound_ns / 1e9:.1f} s); its samples keep their recorded "
            f"publish times (check the hosts' clocks: chronyc tracking)",
        )
