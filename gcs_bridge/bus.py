"""The gateway's side of the bus: the latest payload per (kind, vehicle) in an inbox that wakes
the loop (:class:`Inbox`), states and readings drained from Zenoh's ring buffers
(:class:`Streams`), and one ordered command queue per vehicle (:class:`Commander`). See
docs/qgroundcontrol.md ("Inside the gateway").
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import logging
import os
import threading
from collections.abc import Callable

import msgspec
import zenoh

from swarmbus.codec import decode_or_none
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import (
    Command,
    CommandReply,
    GcsHeartbeat,
    RejectCode,
    Setpoint,
)
from swarmbus.reqrep import BadReply, RequestError, ask, command_reply
from swarmbus.session import payload_or_none
from swarmbus.views import StateHead, TickView

log = logging.getLogger(__name__)

KIND_STATE = "state"
KIND_STATUS = "status"
KIND_READING = "concentration"
MAX_QUEUED_COMMANDS = 64
STREAM_POLL_S = 0.002  # while states / readings flow: how often the loop takes the newest
STREAM_IDLE_POLL_S = 0.05  # while they do not
# Streams where only the newest matters: a queued one is replaced, never queued behind.
_LATEST_WINS = (GcsHeartbeat, Setpoint)


class Waker:
    """A self-pipe: ``wake()`` from any thread makes the loop's select return."""

    def __init__(self) -> None:
        self._r, self._w = os.pipe()
        os.set_blocking(self._r, False)
        os.set_blocking(self._w, False)
        self._pending = threading.Event()

    def fileno(self) -> int:
        return self._r

    def wake(self) -> None:
        if not self._pending.is_set():
            self._pending.set()
            with contextlib.suppress(BlockingIOError, OSError):
                os.write(self._w, b"x")

    def drain(self) -> None:
        """Empty the pipe, then re-arm. In this order: a wake() between the two finds
        ``pending`` still set and writes nothing, but its work is taken after ``drain``."""
        with contextlib.suppress(BlockingIOError, OSError):
            while os.read(self._r, 4096):
                pass
        self._pending.clear()

    def close(self) -> None:
        os.close(self._r)
        os.close(self._w)


class Inbox:
    """Latest state / status / reading payload per vehicle, and callbacks posted to the loop."""

    def __init__(self, waker: Waker) -> None:
        self._waker = waker
        self._lock = threading.Lock()
        self._latest: dict[tuple[str, str], bytes] = {}
        self._calls: collections.deque[Callable[[], None]] = collections.deque()

    def put(self, kind: str, vehicle_id: str, payload: bytes) -> None:
        with self._lock:
            self._latest[(kind, vehicle_id)] = payload
        self._waker.wake()

    def post(self, call: Callable[[], None]) -> None:
        self._calls.append(call)
        self._waker.wake()

    def take(self) -> tuple[dict[tuple[str, str], bytes], list[Callable[[], None]]]:
        with self._lock:
            latest, self._latest = self._latest, {}
        calls = []
        while self._calls:
            calls.append(self._calls.popleft())
        return latest, calls


Readings = zenoh.Subscriber[zenoh.handlers.Handler[zenoh.Sample]]


class Streams:
    """Ticks (every vehicle's state in one ``sim/tick`` message) and every vehicle's readings
    in ring buffers; the loop takes all ticks (a telemetry stream may be due at any of them)
    and the newest reading of each vehicle. Readings can be paused (nobody listens for
    them): Zenoh then stops sending them here at all."""

    def __init__(self, session: zenoh.Session, keys: Keys, vehicle_ids: set[str]) -> None:
        self._session = session
        self._keys = keys
        self._tick_key = keys.tick()
        self._ids = vehicle_ids
        n = max(1, len(vehicle_ids))
        self._readings_ring = max(1024, 16 * n)  # the newest of each vehicle stays
        self._readings: Readings | None = self._subscribe_readings()
        # as many ticks as the per-vehicle state rings held states (>= 16 ticks)
        self._ticks = session.declare_subscriber(
            self._tick_key, zenoh.handlers.RingChannel(max(16, 1024 // n))
        )
        self._index: dict[str, int] = {}  # vehicle id → position of its state in a tick
        self._index_len = -1  # the number of states the index was learnt from

    def _subscribe_readings(self) -> Readings:
        return self._session.declare_subscriber(
            self._keys.all_vehicle_concentration(),
            zenoh.handlers.RingChannel(self._readings_ring),
        )

    def pause_readings(self) -> None:
        """Stop receiving readings until :meth:`resume_readings`."""
        if self._readings is not None:
            self._readings.undeclare()
            self._readings = None

    def resume_readings(self) -> None:
        if self._readings is None:
            self._readings = self._subscribe_readings()

    def drain(self, latest: dict[tuple[str, str], bytes], ticks: list[TickView]) -> int:
        """The newest reading per vehicle into ``latest``, every tick (in order) into
        ``ticks``; how many samples came."""
        count = 0
        vehicle_id_of = self._keys.vehicle_id_of
        while self._readings is not None and (sample := self._readings.try_recv()) is not None:
            count += 1
            try:
                vid = vehicle_id_of(str(sample.key_expr))
            except KeyNameError:
                continue
            data = payload_or_none(sample, "a reading", log) if vid in self._ids else None
            if data is not None:
                latest[(KIND_READING, vid)] = data
        while (sample := self._ticks.try_recv()) is not None:
            count += 1
            data = payload_or_none(sample, "a tick", log)
            if data is None:
                continue
            view = decode_or_none(data, TickView, "a tick", log, self._tick_key)
            if view is None:
                continue
            if len(view.states) == self._index_len or self.learn(view):
                ticks.append(view)
        return count

    def newest_tick(self) -> TickView | None:
        """Only the newest tick (older ones are dropped undecoded); readings are left."""
        newest = None
        while (sample := self._ticks.try_recv()) is not None:
            newest = sample
        data = None if newest is None else payload_or_none(newest, "a tick", log)
        if data is None:
            return None
        view = decode_or_none(data, TickView, "a tick", log, self._tick_key)
        if view is None:
            return None
        return view if len(view.states) == self._index_len or self.learn(view) else None

    def learn(self, view: TickView) -> bool:
        """Where each served vehicle's state is in ``view`` (the physics keeps the order, so
        this runs once, and again only when a tick's layout changes)."""
        ids = []
        for raw in view.states:  # through swarmbus.codec: garbage may raise UnicodeDecodeError
            head = decode_or_none(
                memoryview(raw), StateHead, "a tick's states", log, self._tick_key, "states"
            )
            if head is None:
                return False
            ids.append(head.vehicle_id)
        self._index = {vid: i for i, vid in enumerate(ids) if vid in self._ids}
        self._index_len = len(ids)
        return True

    def raw_state(self, view: TickView, vehicle_id: str) -> msgspec.Raw | None:
        i = self._index.get(vehicle_id)
        return view.states[i] if i is not None and i < len(view.states) else None

    def undeclare(self) -> None:
        self.pause_readings()
        self._ticks.undeclare()


def subscribe_statuses(
    session: zenoh.Session, keys: Keys, vehicle_ids: set[str], inbox: Inbox
) -> zenoh.Subscriber[None]:
    """Every vehicle's status into ``inbox`` (which wakes the loop)."""
    return session.declare_subscriber(
        keys.all_vehicle_status(), _handler(keys, vehicle_ids, inbox, KIND_STATUS)
    )


def _handler(
    keys: Keys, vehicle_ids: set[str], inbox: Inbox, kind: str
) -> Callable[[zenoh.Sample], None]:
    def on_sample(sample: zenoh.Sample) -> None:
        try:
            vid = keys.vehicle_id_of(str(sample.key_expr))
        except KeyNameError:
            return
        data = payload_or_none(sample, kind, log) if vid in vehicle_ids else None
        if data is not None:
            inbox.put(kind, vid, data)

    return on_sample


Done = Callable[[CommandReply], None]


@dataclasses.dataclass(eq=False)
class Commander:
    """Sends one vehicle's commands in order, one query at a time; results go to the loop.

    A query that gets no reply within ``timeout_s`` ends as FAILED ("no reply"); an error reply
    (undecodable command) ends as INVALID. Ground-control heartbeats and offboard setpoints
    never queue behind their own kind: a newer one replaces the one still waiting.
    """

    session: zenoh.Session
    key: str
    vehicle_id: str
    timeout_s: float
    inbox: Inbox
    _lock: threading.Lock = dataclasses.field(default_factory=threading.Lock, init=False)
    _queue: collections.deque[tuple[Command, Done]] = dataclasses.field(
        default_factory=collections.deque, init=False
    )
    _busy: bool = dataclasses.field(default=False, init=False)

    def submit(self, command: Command, done: Done) -> None:
        with self._lock:
            if isinstance(command, _LATEST_WINS):
                for i, (queued, _) in enumerate(self._queue):
                    if type(queued) is type(command):
                        self._queue[i] = (command, done)
                        return
            if len(self._queue) >= MAX_QUEUED_COMMANDS:
                reply = self._failed("too many commands waiting")
                self.inbox.post(lambda: done(reply))
                return
            self._queue.append((command, done))
            if self._busy:
                return
            self._busy = True
        self._start_next()

    def _failed(self, reason: str, code: RejectCode = RejectCode.FAILED) -> CommandReply:
        return CommandReply(vehicle_id=self.vehicle_id, accepted=False, code=code, reason=reason)

    def _start_next(self) -> None:
        with self._lock:
            if not self._queue:
                self._busy = False
                return
            command, done = self._queue.popleft()
        name = type(command).__name__

        def on_done(outcome: CommandReply | RequestError) -> None:
            if isinstance(outcome, BadReply):
                log.warning("%s: bad reply to %s: %s", self.key, name, outcome)
            result = command_reply(self.vehicle_id, outcome)
            self.inbox.post(lambda: done(result))
            self._start_next()

        ask(self.session, self.key, command, CommandReply, self.timeout_s, on_done)
