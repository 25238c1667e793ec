"""The ``recorder`` role: every message under the world's prefix to one MCAP file.

Zenoh delivers samples on its own threads; the callback only stamps and queues them (it must never
block, or publishers with the ``drop`` congestion policy would lose messages upstream). A writer
thread transcodes and writes them (:class:`~recorder.sink.McapSink`). Nothing is dropped
silently: per-key counts are kept, a queue that falls behind is logged and recorded as an event,
and only a queue at its hard limit drops — counted, logged as an error and recorded. Messages lost
in Zenoh before they reach the recorder (publishers use the ``drop`` congestion policy) cannot be
seen directly; for the streams that carry one per tick (``vehicle/<id>/state``, ``sim/tick``) a
jump in ``tick`` is counted, logged and recorded as a ``gap`` event.

The recorder acknowledges every ``NodeHealth`` it records from another node by publishing its own
health with ``detail = "heard <name> <state>"``: a publisher that must not lose its first messages
waits for that acknowledgement (:mod:`recorder.handshake`) before it starts.

A write the disk refuses (full, I/O error) in the spool or the MCAP file does not stop the
process: the recorder abandons the segment (it ends after its last complete chunk, as a killed
recorder's does), says so on its health (``state = error``, the reason in ``detail``), logs and
counts what it cannot record, and every ``retry_s`` checks the free space; once
``resume_free_bytes`` are free it continues in the next segment, recovers from the abandoned
segment's spool what that segment lacks, and records the gap there (:class:`~recorder.schema.
SegmentGap` with its ``reason``), as a restarted recorder does.
"""

from __future__ import annotations

import logging
import os
import queue
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Annotated, Self

import msgspec
import zenoh

from recorder import schema as sch
from recorder.clock_check import ClockCheck
from recorder.foxglove.scene import (
    FoxgloveScene,
)
from recorder.reader import RecordingError, SegmentEnd, segment_end
from recorder.segments import next_segment
from recorder.sink import DEFAULT_CHUNK_BYTES, DEFAULT_CHUNK_INTERVAL_S, McapSink
from recorder.spool import (
    DEFAULT_FSYNC_INTERVAL_S,
    Spool,
    read_durable,
    read_spool,
    remove_spool,
)
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    NodeHealth,
    NodeState,
    PlumeInfo,
    PlumeInfoQuery,
    SimTick,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime, package_version
from swarmbus.options import RoleOptions, role_main
from swarmbus.reqrep import RequestError, request
from swarmbus.scenario import Scenario
from swarmbus.session import payload_or_none
from swarmbus.view_feed import fetch_mesh, isosurface_queries

log = logging.getLogger(__name__)

HealthPublisher = Callable[[str, NodeState | None], None]  # detail, new state (None: same)
SegmentOpener = Callable[[Path], tuple[McapSink, Spool | None]]


class RecorderOptions(RoleOptions, frozen=True, kw_only=True):
    """The recorder role's options (``--set KEY=VALUE``)."""

    out: Annotated[str, msgspec.Meta(min_length=1)] = "recording.mcap"
    """The recording (default: ``plumeswarm-<world>-<UTC time>.mcap``, :meth:`defaults`)."""
    chunk_interval_s: Annotated[float, msgspec.Meta(gt=0.0, le=3600.0)] = DEFAULT_CHUNK_INTERVAL_S
    chunk_bytes: Annotated[int, msgspec.Meta(ge=1, le=2**31)] = DEFAULT_CHUNK_BYTES
    max_backlog: Annotated[int, msgspec.Meta(ge=1, le=10**9)] = 2_000_000
    """Hard limit of queued messages (memory), then drop and count."""
    max_backlog_bytes: Annotated[int, msgspec.Meta(ge=2**20, le=2**40)] = 256 * 2**20
    """Hard limit of queued payload bytes (memory), then drop and count."""
    behind_backlog: Annotated[int, msgspec.Meta(ge=1, le=10**9)] = 50_000
    """Falling behind above this many queued messages …"""
    behind_age_s: Annotated[float, msgspec.Meta(gt=0.0, le=3600.0)] = 2.0
    """… or when the oldest written message waited this long."""
    health_period_s: Annotated[float, msgspec.Meta(gt=0.0, le=3600.0)] = 1.0
    query_plume_info: bool = True
    resume: bool = False
    """``out`` exists (a killed predecessor's): continue in its next segment."""
    foxglove: bool = True
    """Also write the Foxglove channels (recorder.foxglove.scene)."""
    spool: bool = True
    """Write-ahead spool (recorder.spool): a kill loses nothing received."""
    spool_fsync_s: Annotated[float, msgspec.Meta(gt=0.0, le=3600.0)] = DEFAULT_FSYNC_INTERVAL_S
    """The spool is forced to the disk (fsync) at this interval."""
    retry_s: Annotated[float, msgspec.Meta(gt=0.0, le=3600.0)] = 1.0
    """After a write error: how often to check whether recording can go on."""
    resume_free_bytes: Annotated[int, msgspec.Meta(ge=0, le=2**50)] = 1 << 20
    """After a write error: recording goes on (in a new segment) once this much is free."""

    @classmethod
    def defaults(cls, scenario: Scenario) -> Self:
        stamp = datetime.now(UTC).strftime("%Y%m%d-%H%M%S")
        return cls(out=f"plumeswarm-{scenario.world.name}-{stamp}.mcap")


# key, payload, receive time (ns), publish time (ns, the sample's timestamp), is a query reply
Item = tuple[str, bytes, int, int | None, bool]


class _Ticked(msgspec.Struct):
    tick: int


_TICK = msgspec.msgpack.Decoder(_Ticked)  # the tick of a SimTick or VehicleState payload


def _tick_of(payload: bytes) -> int | None:
    try:
        return _TICK.decode(payload).tick
    except msgspec.DecodeError:
        return None


def publish_time_ns(sample: zenoh.Sample) -> int | None:
    """The publisher's time of ``sample`` (ns since the Unix epoch), None if it has none."""
    if sample.timestamp is None:
        return None
    return int(sample.timestamp.get_time_as_ntp64().as_nanos())


class Recorder:
    """Subscribes to ``keys.everything()`` and writes what arrives to ``sink``."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        name: str,
        sink: McapSink,
        options: RecorderOptions,
        publish_health: HealthPublisher,
        previous_segment: Path | None = None,
        scenario: Scenario | None = None,
        spool: Spool | None = None,
        first: Path | None = None,
        open_segment: SegmentOpener | None = None,
    ) -> None:
        self._session = session
        self._spool = spool
        # After a write error: continue in the next segment of ``first`` (opened by
        # ``open_segment``); without them the recorder stays in error until it stops.
        self._first = first
        self._open_segment = open_segment
        self._failure: str | None = None  # the write error, until recording goes on
        self._abandoned = False  # the failed segment's files are closed
        self.write_lost = 0  # messages received while in error (not recorded)
        self._retry_at = 0.0
        self._last_sync = time.monotonic()
        self._gap_reason = ""
        self._last_log_ns = 0  # receive times are made strictly increasing (queue order)
        self._written_ns = -1  # receive time of the last message written
        self.recovered = 0  # messages recovered from the previous segment's spool
        self.backfilled = 0  # ticks and states the physics re-sent that we had not got
        # (key, tick) of the per-tick streams the killed recorder received (its spool) and of
        # the physics's re-sent ones taken: a re-sent one is recorded only if it is not here
        self._have: set[tuple[str, int]] = set()
        self._have_max: dict[str, int] = {}  # the newest tick of each key in that spool
        self._scenario = scenario
        # Foxglove's channels, converted on the writer thread from the messages it decodes
        # anyway; decimated in simulation time, so their cost does not grow with the tick rate.
        self._foxglove = FoxgloveScene(scenario) if options.foxglove else None
        self._keys = keys
        self._name = name
        self._sink = sink
        self._opts = options
        self._publish_health = publish_health
        self._queue: queue.SimpleQueue[Item] = queue.SimpleQueue()
        self._lock = threading.Lock()
        self.received: Counter[str] = Counter()
        self.dropped: Counter[str] = Counter()
        self.refused: Counter[str] = Counter()  # over [network] max_message_size_bytes
        self.tick_gaps: Counter[str] = Counter()  # messages missing from per-tick streams
        self._last_tick: dict[str, int] = {}
        self._durable_tick: dict[str, int] = {}  # the newest tick of each key in a closed chunk
        self._gaps_reported = 0
        self._received_total = 0
        self._dropped_total = 0
        self._taken_total = 0
        self._dropped_reported = 0
        self._queued_bytes = 0  # payload bytes queued, not yet written
        self._behind = False
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name="recorder-writer", daemon=True)
        # publishers whose clocks differ from ours beyond Zenoh's bound: logged at once,
        # recorded as ``clock`` events by the writer thread
        self._clock_findings: list[tuple[str, str]] = []
        self._clock = ClockCheck(
            session, lambda key: key.startswith(f"{keys.prefix}/node/"), self._clock_finding
        )
        self._sub: zenoh.Subscriber[None] | None = None
        self._last_health = 0.0
        self._info_thread = threading.Thread(
            target=self._query_plume_info, name="recorder-plume-info", daemon=True
        )
        # A restarted recorder: the gap since the previous segment, written once the previous
        # segment has been read (on its own thread: recording starts at once) and the first
        # tick of this segment has arrived.
        self._previous = previous_segment
        self._previous_end: SegmentEnd | None = None
        self._gap_pending = previous_segment is not None
        self._first_log_ns: int | None = None
        self._first_tick: SimTick | None = None
        self._started_s = time.monotonic()
        self._scan_thread = threading.Thread(
            target=self._scan_previous, name="recorder-previous-segment", daemon=True
        )

    # -- Zenoh thread --------------------------------------------------------------------------
    def _on_sample(self, sample: zenoh.Sample) -> None:
        now = time.time_ns()
        key = str(sample.key_expr)
        original = self._keys.backfilled(key)
        if original is not None:
            self._on_backfill(original, sample, now)
            return
        payload = self._within_limit(key, sample)
        if payload is None:
            return
        self._clock.observe(key, sample, now)
        with self._lock:
            if (
                self._received_total - self._taken_total >= self._opts.max_backlog
                or self._queued_bytes + len(payload) > self._opts.max_backlog_bytes
            ):
                self.dropped[key] += 1
                self._dropped_total += 1
                return
            self.received[key] += 1
            self._received_total += 1
            self._enqueue(key, payload, now, publish_time_ns(sample), False)

    def _within_limit(self, key: str, sample: zenoh.Sample) -> bytes | None:
        """The sample's payload, or None (logged, counted in ``refused``, not recorded) when it
        is over ``[network] max_message_size_bytes``."""
        payload = payload_or_none(sample, "a message", log)
        if payload is None:
            with self._lock:
                self.refused[key] += 1
        return payload

    def _enqueue(
        self, key: str, payload: bytes, now_ns: int, publish_ns: int | None, is_reply: bool
    ) -> None:
        """Stamp, spool and queue one message (the caller holds the lock: one order for all);
        while in error (or when the spool's write fails) count it as not recorded."""
        if self._failure is None:
            self._last_log_ns = now_ns = max(now_ns, self._last_log_ns + 1)
            item = (key, payload, now_ns, publish_ns, is_reply)
            try:
                if self._spool is not None:
                    self._spool.append(item)
            except OSError as exc:
                self._failure = f"spool of {self._sink.path.name}: {exc.strerror or exc}"
            else:
                self._queued_bytes += len(payload)
                self._queue.put(item)
                return
        self.write_lost += 1
        if not is_reply:
            self._taken_total += 1  # never queued: not in the backlog

    def _on_backfill(self, key: str, sample: zenoh.Sample, now: int) -> None:
        """A tick or state the physics re-sent after our restart: recorded under its own key
        if the killed recorder never received it (published after it died)."""
        payload = self._within_limit(key, sample)
        tick = None if payload is None else _tick_of(payload)
        if payload is None or self._previous is None or tick is None:
            return
        with self._lock:
            if (key, tick) in self._have or tick <= self._have_max.get(key, -1):
                return
            self._have.add((key, tick))
            self.backfilled += 1
            self.received[key] += 1
            self._received_total += 1
            self._enqueue(key, payload, now, publish_time_ns(sample), False)

    def _clock_finding(self, key: str, detail: str) -> None:
        log.warning("CLOCK SKEW: %s", detail)
        with self._lock:
            self._clock_findings.append((key, detail))

    def _put_reply(self, key: str, payload: bytes) -> None:
        with self._lock:
            self._enqueue(key, payload, time.time_ns(), None, True)

    def _recover(self) -> None:
        """Queue, first, what the previous segment's spool holds that its file does not (the
        killed recorder's queue and open chunk), stamped now; its spool is then ours. Recording
        goes on (after a write error) from here."""
        previous = self._previous
        if previous is None:
            return
        durable_ns, durable_ticks = read_durable(previous)
        with self._lock:
            self._failure = None
            # the ticks in the file's closed chunks, which a spool just rotated no longer holds
            for key, newest in durable_ticks.items():
                self._have_max[key] = max(newest, self._have_max.get(key, -1))
            for key, payload, log_ns, publish_ns, is_reply in read_spool(previous):
                tick = _tick_of(payload) if not is_reply else None
                if tick is not None:
                    self._have_max[key] = max(tick, self._have_max.get(key, -1))
                if log_ns > durable_ns:
                    self._enqueue(key, payload, time.time_ns(), publish_ns, is_reply)
                    self.recovered += 1
                    if not is_reply:
                        self.received[key] += 1
                        self._received_total += 1
        remove_spool(previous)
        if self.recovered:
            log.warning(
                "recovered %d messages from %s's spool (received, not yet written)",
                self.recovered,
                previous.name,
            )

    # -- lifecycle -----------------------------------------------------------------------------
    def start(self) -> None:
        self._sink.write_event(sch.RecorderEvent(kind=sch.EventKind.STARTED, detail=self._name))
        if self._gap_pending:
            self._scan_thread.start()
        self._recover()
        self._thread.start()
        self._sub = self._session.declare_subscriber(self._keys.everything(), self._on_sample)
        if self._opts.query_plume_info:
            self._info_thread.start()

    def stop(self, timeout_s: float = 30.0) -> bool:
        """Stop subscribing, write what is queued, close the file with its summary; whether
        the recording is complete (False: it stopped in error)."""
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None
        self._stopping.set()
        if self._info_thread.is_alive():
            self._info_thread.join(5.0)
        self._thread.join(timeout_s)
        if self._thread.is_alive():
            log.error("recorder writer did not finish within %.0f s", timeout_s)
        if self._failure is None:
            try:
                self._finish()
            except OSError as exc:
                self._failure = f"closing {self._sink.path.name}: {exc.strerror or exc}"
        if self._failure is None:
            return True
        if not self._abandoned:
            self._abandon()
        log.error(
            "recording stopped in error (%s): %s ends at its last complete chunk; "
            "%d messages not recorded",
            self._failure,
            self._sink.path,
            self.write_lost,
        )
        return False

    def _finish(self) -> None:
        """Write the last reports and events and close the file with its summary."""
        self._report_drops()
        self._report_gaps()
        if self._gap_pending:
            self._scan_thread.join(GAP_SCAN_TIMEOUT_S)
            self._write_segment_gap(force=True)
        self._sink.write_event(self._event(sch.EventKind.STOPPED))
        self._sink.close(self.summary())
        if self._spool is not None:
            self._spool.close(remove=not self._thread.is_alive())  # all of it is in the file
        log.info("recording closed: %s (%d messages)", self._sink.path, self.written_total)

    @property
    def written_total(self) -> int:
        return sum(self._sink.written.values())

    @property
    def backlog(self) -> int:
        with self._lock:
            return self._received_total - self._taken_total

    def summary(self) -> dict[str, str]:
        with self._lock:
            received = dict(self.received)
            dropped = dict(self.dropped)
            refused = dict(self.refused)
        return {
            "received": msgspec.json.encode(received).decode(),
            "dropped": msgspec.json.encode(dropped).decode(),
            "refused": msgspec.json.encode(refused).decode(),
            "undecodable": msgspec.json.encode(dict(self._sink.undecodable)).decode(),
            "tick_gaps": msgspec.json.encode(dict(self.tick_gaps)).decode(),
            "received_total": str(sum(received.values())),
            "dropped_total": str(sum(dropped.values())),
        }

    def _event(self, kind: sch.EventKind, detail: str = "") -> sch.RecorderEvent:
        with self._lock:
            return sch.RecorderEvent(
                kind=kind,
                detail=detail,
                backlog=self._received_total - self._taken_total,
                dropped=self._dropped_total,
                received=self._received_total,
                written=self._taken_total,
            )

    # -- writer thread -------------------------------------------------------------------------
    def _run(self) -> None:
        while True:
            if self._failure is not None:
                if self._stopping.is_set():
                    return
                self._while_failed()
                continue
            try:
                if not self._write_some():
                    return
            except OSError as exc:
                with self._lock:
                    self._failure = self._failure or (
                        f"{self._sink.path.name}: {exc.strerror or exc}"
                    )

    def _write_some(self) -> bool:
        """Write what is queued, then housekeeping; False once stopping with nothing queued."""
        try:
            item = self._queue.get(timeout=0.05)
        except queue.Empty:
            if self._stopping.is_set():
                return False
            self._housekeeping()
            return True
        self._write(item)
        for _ in range(2000):  # drain a burst before the next housekeeping
            try:
                self._write(self._queue.get_nowait())
            except queue.Empty:
                break
        self._housekeeping(age_s=(time.time_ns() - item[2]) / 1e9)
        return True

    # -- write errors --------------------------------------------------------------------------
    def _while_failed(self) -> None:
        """In error: abandon the segment (once), drop what is queued (the spool has it), say
        so on the health every period, and try to go on every ``retry_s``."""
        if not self._abandoned:
            self._abandon()
        drained = 0
        while True:
            try:
                drained += not self._queue.get_nowait()[4]
            except queue.Empty:
                break
        with self._lock:
            self._taken_total += drained
            if self._spool is None:
                self.write_lost += drained  # no spool to recover them from
        now = time.monotonic()
        if now - self._last_health >= self._opts.health_period_s:
            self._last_health = now
            self._publish_health(self._failure_detail(), NodeState.ERROR)
        if now >= self._retry_at:
            self._retry_at = now + self._opts.retry_s
            try:
                self._try_resume()
            except OSError as exc:  # the new segment failed at once: abandoned in turn
                with self._lock:
                    self._failure = f"{self._sink.path.name}: {exc.strerror or exc}"
        else:
            self._stopping.wait(0.05)

    def _failure_detail(self) -> str:
        return f"write error: {self._failure}; {self.write_lost} messages not recorded"

    def _abandon(self) -> None:
        self._abandoned = True
        log.error(
            "RECORDER WRITE ERROR: %s; %s abandoned, recording goes on in a new segment once "
            "%d bytes are free",
            self._failure,
            self._sink.path.name,
            self._opts.resume_free_bytes,
        )
        self._sink.abandon()
        if self._spool is not None:
            self._spool.abandon()
        self._last_health = time.monotonic()
        self._publish_health(self._failure_detail(), NodeState.ERROR)

    def _try_resume(self) -> None:
        """Go on in the next segment if the disk has room again."""
        if self._open_segment is None or self._first is None:
            return
        old = self._sink.path
        try:
            disk = os.statvfs(old.parent)
            if disk.f_bavail * disk.f_frsize < self._opts.resume_free_bytes:
                return
        except OSError:
            return
        _, path = next_segment(self._first)
        try:
            sink, spool = self._open_segment(path)
        except OSError as exc:
            log.error("recording cannot go on in %s yet: %s", path.name, exc.strerror or exc)
            path.unlink(missing_ok=True)
            remove_spool(path)
            return
        reason = f"write error: {self._failure}"
        with self._lock:
            self._sink, self._spool = sink, spool
        self._abandoned = False
        self._previous, self._previous_end, self._gap_pending = old, None, True
        self._gap_reason = reason
        self._first_log_ns, self._first_tick = None, None
        self._started_s = time.monotonic()
        self._have.clear()
        self._have_max = self._durable_tick  # re-sent ticks newer than these are taken
        self._last_tick, self._durable_tick = {}, {}
        sink.write_event(sch.RecorderEvent(kind=sch.EventKind.STARTED, detail=self._name))
        sink.write_event(self._event(sch.EventKind.WRITE_ERROR, f"{old.name}: {reason}"))
        self._scan_thread = threading.Thread(
            target=self._scan_previous, name="recorder-previous-segment", daemon=True
        )
        self._scan_thread.start()
        self._recover()
        log.warning("recording goes on in %s after %s", path.name, reason)
        self._publish_health(f"recording in {path.name} after {reason}", NodeState.READY)

    def _write(self, item: Item) -> None:
        key, payload, log_time_ns, publish_ns, is_reply = item
        self._written_ns = log_time_ns
        with self._lock:
            self._queued_bytes -= len(payload)
        if is_reply:
            reply = sch.decode_bus(payload)
            self._sink.write_reply(key, reply, log_time_ns)
            self._to_foxglove(reply, log_time_ns)
            return
        with self._lock:
            self._taken_total += 1
        message = self._sink.write_bus(key, payload, log_time_ns, publish_ns)
        self._to_foxglove(message, log_time_ns)
        if self._first_log_ns is None:
            self._first_log_ns = log_time_ns
        if isinstance(message, SimTick) and self._first_tick is None:
            self._first_tick = message
        if isinstance(message, VehicleState | SimTick):
            self._check_tick(key, message.tick)
        elif isinstance(message, NodeHealth) and message.name != self._name:
            self._publish_health(f"heard {message.name} {message.state}", None)

    def _to_foxglove(self, message: msgspec.Struct | None, log_time_ns: int) -> None:
        if self._foxglove is not None and message is not None:
            for out in self._foxglove.feed(message, log_time_ns):
                self._sink.write_foxglove(out)

    def _check_tick(self, key: str, tick: int) -> None:
        last = self._last_tick.get(key)
        self._last_tick[key] = tick
        if last is not None and tick > last + 1:  # backwards: a restart or a replay, not a loss
            self.tick_gaps[key] += tick - last - 1

    def _housekeeping(self, age_s: float = 0.0) -> None:
        if self._gap_pending:
            self._write_segment_gap()
        if self._spool is None:
            if self._sink.maybe_close_chunk():
                self._durable_tick = dict(self._last_tick)
        else:
            # the chunk and its mark back to back, with no wait for the lock between them: a
            # kill after the chunk but before its mark records the chunk again from the spool
            with self._lock:
                if self._sink.maybe_close_chunk():
                    self._durable_tick = dict(self._last_tick)
                    self._spool.rotate(self._written_ns, self._durable_tick)
        self._watch_backlog(age_s)
        self._report_drops()
        if self._clock_findings:
            with self._lock:
                findings, self._clock_findings = self._clock_findings, []
            for key, detail in findings:
                event = self._event(sch.EventKind.CLOCK, detail)
                self._sink.write_event(msgspec.structs.replace(event, key=key))
        now = time.monotonic()
        if self._spool is not None and now - self._last_sync >= self._opts.spool_fsync_s:
            self._last_sync = now
            self._spool.sync()  # the writer thread alone changes the spool's files
        if now - self._last_health >= self._opts.health_period_s:
            self._last_health = now
            self._report_gaps()
            self._publish_health(
                f"recording {self._sink.path.name}: {self.written_total} messages, "
                f"backlog {self.backlog}, dropped {self._dropped_total}",
                None,
            )

    def _watch_backlog(self, age_s: float) -> None:
        backlog = self.backlog
        behind = backlog > self._opts.behind_backlog or age_s > self._opts.behind_age_s
        if behind and not self._behind:
            detail = f"write queue falling behind: {backlog} queued, oldest {age_s:.1f} s old"
            log.warning("RECORDER BEHIND: %s", detail)
            self._sink.write_event(self._event(sch.EventKind.BEHIND, detail))
        elif self._behind and not behind and backlog < self._opts.behind_backlog // 10:
            log.warning("recorder caught up (backlog %d)", backlog)
            self._sink.write_event(self._event(sch.EventKind.CAUGHT_UP))
        else:
            return
        self._behind = behind

    def _report_gaps(self) -> None:
        total = sum(self.tick_gaps.values())
        if total > self._gaps_reported:
            worst = self.tick_gaps.most_common(1)[0][0]
            detail = (
                f"{total - self._gaps_reported} messages missing from per-tick streams "
                f"(lost before reaching the recorder); most on {worst}"
            )
            log.warning("RECORDER SAW GAPS: %s", detail)
            event = self._event(sch.EventKind.GAP, detail)
            self._sink.write_event(msgspec.structs.replace(event, lost_upstream=total))
            self._gaps_reported = total

    def _report_drops(self) -> None:
        with self._lock:
            dropped = self._dropped_total
        if dropped > self._dropped_reported:
            detail = (
                f"{dropped - self._dropped_reported} messages dropped (queue full: at most "
                f"{self._opts.max_backlog} messages, {self._opts.max_backlog_bytes} bytes)"
            )
            log.error("RECORDER DROPPED MESSAGES: %s; %d in total", detail, dropped)
            self._sink.write_event(self._event(sch.EventKind.DROPPED, detail))
            self._dropped_reported = dropped

    # -- a restarted recorder's gap ------------------------------------------------------------
    def _scan_previous(self) -> None:
        assert self._previous is not None
        try:
            end = segment_end(self._previous)
        except RecordingError as exc:
            log.error("cannot read the previous segment for the gap record: %s", exc)
            end = SegmentEnd(0, True, None, None, None)
        self._previous_end = end

    def _write_segment_gap(self, force: bool = False) -> None:
        """Once the previous segment is read and this one's first tick is here (or waiting for
        it is pointless), write the gap on its channel and a ``resumed`` event."""
        end = self._previous_end
        if end is None or self._previous is None:
            if force:
                log.error("previous segment %s not read in time: no gap record", self._previous)
                self._gap_pending = False
            return
        waited = time.monotonic() - self._started_s
        if self._first_tick is None and not force and waited < GAP_TICK_WAIT_S:
            return
        self._gap_pending = False
        first = self._first_tick
        gap_s = None
        if end.last_log_time_ns is not None and self._first_log_ns is not None:
            gap_s = (self._first_log_ns - end.last_log_time_ns) / 1e9
        missing = None
        if end.last_tick is not None and first is not None:
            missing = first.tick - end.last_tick - 1
        gap = sch.SegmentGap(
            previous_segment=self._previous.name,
            previous_truncated=end.truncated,
            previous_messages=end.messages,
            previous_last_log_time_ns=end.last_log_time_ns,
            previous_last_tick=end.last_tick,
            previous_last_sim_time_s=end.last_sim_time_s,
            first_log_time_ns=self._first_log_ns,
            first_tick=first.tick if first is not None else None,
            first_sim_time_s=first.sim_time_s if first is not None else None,
            gap_s=gap_s,
            ticks_missing=missing,
            reason=self._gap_reason,
        )
        self._sink.write_gap(gap)
        detail = (
            f"continuing after {self._previous.name} ({end.messages} messages"
            f"{', cut short' if end.truncated else ''}): "
            + (f"{gap_s:.2f} s" if gap_s is not None else "unknown time")
            + " not recorded"
            + (f", ticks {end.last_tick} → {first.tick}" if missing is not None and first else "")
            + (f"; {self.recovered} messages recovered from its spool" if self.recovered else "")
        )
        log.warning("RECORDER RESUMED: %s", detail)
        self._sink.write_event(self._event(sch.EventKind.RESUMED, detail))

    def _query_plume_info(self) -> None:
        # plume/info is a queryable, not a publication: ask until answered, so that a report
        # can draw the field the vehicles flew through.
        key = self._keys.plume_info()
        while not self._stopping.wait(0.0):
            try:
                info = request(self._session, key, PlumeInfoQuery(), PlumeInfo, 1.0)
            except RequestError as exc:
                log.info("plume info not recorded yet: %s", exc)
                self._stopping.wait(2.0)
                continue
            self._put_reply(key, encode(info))
            log.info("recorded the plume's info")
            if self._foxglove is not None and self._scenario is not None:
                self._query_plume_meshes(self._scenario)
            return

    def _query_plume_meshes(self, scenario: Scenario) -> None:
        # The isosurfaces the viewer draws (same levels and box), for the Foxglove scene; the
        # replies are recorded too, so that ``export foxglove`` draws the same plume.
        key = self._keys.plume_mesh()
        pending = isosurface_queries(scenario)
        while pending and not self._stopping.is_set():
            for query in list(pending):
                mesh = fetch_mesh(self._session, self._keys, query)
                if mesh is not None:
                    self._put_reply(key, encode(mesh))
                    pending.remove(query)
            self._stopping.wait(2.0 if pending else 0.0)


# Zenoh's receive thread needs the GIL for every sample while the writer thread holds it for up
# to the switch interval (5 ms by default); a stalled receive thread back-pressures the link and
# upstream drops follow. A shorter interval reduced that loss at 61k msg/s in
# plumeswarm/bench/recorder.py.
GIL_SWITCH_INTERVAL_S = 0.0005
GAP_TICK_WAIT_S = 10.0  # wall: a lockstep that does not tick (paused, gone) gets a gap without
GAP_SCAN_TIMEOUT_S = 60.0


@role_main(RecorderOptions, "recorder")
def main(ctx: NodeContext, opts: RecorderOptions) -> int:
    """Record until SIGINT/SIGTERM; returns the process exit code."""
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)  # this process is the recorder alone
    metadata = {
        "world": ctx.scenario.world.name,
        "recorder": ctx.name,
        "version": package_version(),
        "started_utc": datetime.now(UTC).isoformat(),
        "scenario": msgspec.json.encode(ctx.scenario).decode(),
    }
    out, previous = Path(opts.out), None
    if opts.resume:
        previous, out = next_segment(out)
    if previous is not None:
        log.warning("%s exists (recorder restarted): continuing in %s", previous, out.name)

    def open_segment(path: Path) -> tuple[McapSink, Spool | None]:
        sink = McapSink(
            path,
            chunk_interval_s=opts.chunk_interval_s,
            chunk_bytes=opts.chunk_bytes,
            metadata=metadata,
        )
        try:
            return sink, Spool(path) if opts.spool else None
        except OSError:
            sink.abandon()
            raise

    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        sink, spool = open_segment(out)
    except OSError as exc:
        log.error("cannot write recording %s: %s", out, exc.strerror or exc)
        return 2
    with NodeRuntime(ctx, role="recorder") as rt:
        recorder = Recorder(
            rt.session,
            rt.keys,
            ctx.name,
            sink,
            opts,
            lambda detail, state: rt.publish_health(state=state, detail=detail),
            previous_segment=previous,
            scenario=ctx.scenario,
            spool=spool,
            first=Path(opts.out),
            open_segment=open_segment,
        )
        recorder.start()
        log.info("recording %s to %s", rt.keys.everything(), out)
        rt.ready()
        rt.stop.wait()
        complete = recorder.stop()
    return 0 if complete else 1
