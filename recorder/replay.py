"""``plumeswarm replay``: publish a recording back onto the bus with its original timing.

Messages go out on the keys they were recorded from, in file order, spaced as they were
published (publish time: the publisher's Zenoh timestamp; the receive time in recordings made
without one), divided by ``speed``. Publishers on hosts whose clocks disagree by more than
Zenoh's bound (0.5 s) are told apart by the recorder's one clock (:class:`Pacing`): a message
stamped further ahead of the newest one so far than it arrived after it does not hold the
rest back, and one stamped behind goes out right after the message before it.
Published bus messages only: the presence plane (``node/*``, other nodes' health would
confuse supervisors), replies the recorder asked for itself, and the recorder's own events
are not replayed. Raw payloads that were not valid messages go out byte for byte, as they
came.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass

import msgspec
import zenoh

from recorder.clock_check import CLOCK_BOUND_S
from recorder.handshake import RecorderNotListening, wait_until_recorded
from recorder.reader import Recorded, Recording, RecordingError
from swarmbus.codec import encode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import NodeState
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import Scenario
from swarmbus.session import Presence

log = logging.getLogger(__name__)


class ReplayError(PlumeswarmError, RuntimeError):
    """A replay that cannot start or finish: one line for the user."""


@dataclass(frozen=True)
class ReplayOptions:
    speed: float = 1.0
    wait_for: tuple[str, ...] = ()  # node names whose liveliness tokens must be up first
    recorded_by: str | None = None  # a recorder that must acknowledge before and after
    timeout_s: float = 30.0


def recorded_world(recording: Recording) -> str:
    world = recording.metadata.get("plumeswarm", {}).get("world", "default")
    try:
        return Keys(world).world
    except KeyNameError as exc:
        raise RecordingError(f"{recording.path}: bad world name in metadata: {exc}") from None


class Pacing:
    """When each recorded message is due, in seconds from the first, by its publish time.

    Publish times come from the publishers' clocks, receive (log) times from the recorder's
    alone. A message stamped more than ``bound_s`` further after the newest publish time so far
    than it was received after that message's receipt comes from a clock that is ahead of that
    one's (after the recording's first message from a host whose clock is behind, say): the
    schedule is moved back so that it is due after that message by their receive times' spacing,
    not by the difference of the clocks."""

    def __init__(self, bound_s: float = CLOCK_BOUND_S) -> None:
        self._bound_ns = round(bound_s * 1e9)
        self._anchor_ns: int | None = None  # the publish time that is due at 0
        self._newest: tuple[int, int] = (0, 0)  # publish and log time of the newest publish

    def due_s(self, publish_ns: int, log_ns: int) -> float:
        if self._anchor_ns is None:
            self._anchor_ns = publish_ns
            self._newest = (publish_ns, log_ns)
        newest_publish, newest_log = self._newest
        if publish_ns > newest_publish:
            excess = (publish_ns - newest_publish) - (log_ns - newest_log)
            if excess > self._bound_ns:
                self._anchor_ns += excess
            self._newest = (publish_ns, log_ns)
        return (publish_ns - self._anchor_ns) / 1e9


def replayable(recording: Recording, keys: Keys) -> Iterator[tuple[Recorded, bytes]]:
    """(record, payload to publish) for every message that replay sends, in order."""
    prefix = keys.prefix + "/"
    for rec in recording.messages():
        if rec.origin != "bus" or not rec.topic.startswith(prefix):
            continue
        if keys.relative(rec.topic).startswith("node/"):
            continue
        message = rec.message()
        yield rec, (encode(message) if message is not None else rec.data)


class _Publishers:
    def __init__(self, session: zenoh.Session) -> None:
        self._session = session
        self._pubs: dict[str, zenoh.Publisher] = {}

    def put(self, key: str, payload: bytes) -> None:
        pub = self._pubs.get(key)
        if pub is None:
            pub = self._pubs[key] = self._session.declare_publisher(key)
        pub.put(payload)

    def close(self) -> None:
        for pub in self._pubs.values():
            pub.undeclare()


def _wait_for_nodes(session: zenoh.Session, keys: Keys, opts: ReplayOptions) -> None:
    if not opts.wait_for:
        return
    presence = Presence(session, keys)
    try:
        wanted = set(opts.wait_for)
        if not presence.wait_for(lambda alive: wanted <= alive, opts.timeout_s):
            missing = ", ".join(sorted(wanted - presence.alive))
            raise ReplayError(
                f"waited {opts.timeout_s:.0f} s for node(s) {missing}; not on the bus"
            )
    finally:
        presence.close()


def _handshake(rt: NodeRuntime, opts: ReplayOptions, state: NodeState) -> None:
    if opts.recorded_by is None:
        return
    try:
        wait_until_recorded(
            rt.session,
            rt.keys,
            rt.ctx.name,
            state,
            lambda: rt.publish_health(state),
            recorder=opts.recorded_by,
            timeout_s=opts.timeout_s,
        )
    except RecorderNotListening as exc:
        raise ReplayError(str(exc)) from None


def replay(recording: Recording, rt: NodeRuntime, opts: ReplayOptions) -> int:
    """Publish ``recording``; returns the number of messages sent (stops early on rt.stop)."""
    _wait_for_nodes(rt.session, rt.keys, opts)
    _handshake(rt, opts, NodeState.READY)
    rt.ready()
    pubs = _Publishers(rt.session)
    sent = 0
    pacing = Pacing()
    start = time.monotonic()
    try:
        for rec, payload in replayable(recording, rt.keys):
            due = start + pacing.due_s(rec.publish_time_ns, rec.log_time_ns) / opts.speed
            delay = due - time.monotonic()
            if delay > 0 and rt.stop.wait(delay):
                break
            if rt.stop.is_set():
                break
            pubs.put(rec.topic, payload)
            sent += 1
    finally:
        pubs.close()
    if not rt.stop.is_set():
        _handshake(rt, opts, NodeState.STOPPING)
    return sent


def run(path: str, scenario: Scenario, connect: list[str], opts: ReplayOptions) -> int:
    """Open, replay, report one line; raises RecordingError / ReplayError for the CLI."""
    if not opts.speed > 0:
        raise ReplayError(f"--speed must be > 0, got {opts.speed}")
    recording = Recording.open(path)
    world = recorded_world(recording)
    scenario = msgspec.structs.replace(
        scenario, world=msgspec.structs.replace(scenario.world, name=world)
    )
    net = scenario.network.with_overrides(connect=connect or None)
    ctx = NodeContext(scenario, net, "replay")
    started = time.monotonic()
    with NodeRuntime(ctx, role="replay") as rt:
        sent = replay(recording, rt, opts)
    log.info("replayed %d messages in %.1f s", sent, time.monotonic() - started)
    return sent
