"""Reading a recording back, in the order it was written — also one cut short by a SIGKILL.

Records are read sequentially (not through the summary index) so that a file without its
summary, whose last chunk is incomplete, yields everything up to its last complete chunk; the
incomplete tail is reported (``truncated``), not raised. Anything that is not an MCAP file, or
is damaged before its end, raises :class:`RecordingError` with one clear line.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import msgspec
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from recorder import schema as sch
from recorder.schema import SegmentGap, gap_from_json
from recorder.segments import SegmentError, recording_files
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import Message as BusMessage
from swarmbus.messages import SimTick

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(PlumeswarmError, RuntimeError):
    """A recording that cannot be read: missing, not MCAP, or damaged."""


class ExportError(PlumeswarmError, RuntimeError):
    """A recording that cannot be converted for another tool (Foxglove, rosbag2): one line
    saying why."""


@dataclass(frozen=True)
class Recorded:
    """One message of a recording."""

    topic: str
    log_time_ns: int
    publish_time_ns: int
    sequence: int
    encoding: str
    schema_name: str
    origin: str  # "bus", "query-reply" (asked by the recorder) or "recorder"
    data: bytes

    @property
    def is_bus_message(self) -> bool:
        return self.encoding == sch.MESSAGE_ENCODING and self.origin in ("bus", "query-reply")

    def message(self) -> BusMessage | None:
        """The typed bus message, or None for raw payloads and recorder events."""
        if not self.is_bus_message:
            return None
        try:
            return sch.from_json(self.data)
        except (msgspec.DecodeError, msgspec.ValidationError) as exc:
            raise RecordingError(f"{self.topic}: stored message is malformed: {exc}") from None

    def event(self) -> sch.RecorderEvent | None:
        if self.topic != sch.EVENTS_TOPIC:
            return None
        return sch.event_from_json(self.data)


@dataclass
class Recording:
    """A recording: one MCAP file, or the segments of one (a recorder restarted after a crash
    continues in ``<name>.1.mcap`` …); iterate :meth:`messages` (once or many times)."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    truncated: bool = False  # a segment ends without its summary (its recorder was killed)
    message_count: int | None = None  # from the summaries, when every segment has one
    segments: list[Path] = field(default_factory=list)  # the files, in order

    def __post_init__(self) -> None:
        if not self.segments:
            self.segments = [self.path]

    @classmethod
    def open(cls, path: str | Path) -> Recording:
        """``path``: a recording's first segment (its later segments are read too), one later
        segment alone, or the directory holding one recording's segments."""
        p = Path(path)
        if not p.exists():
            raise RecordingError(f"{p}: no such file")
        try:
            files = recording_files(p)
        except SegmentError as exc:
            raise RecordingError(str(exc)) from None
        except OSError as exc:
            raise RecordingError(f"{p}: cannot read: {exc.strerror or exc}") from None
        counts = [_check_mcap(f) for f in files]
        total = None if None in counts else sum(c for c in counts if c is not None)
        if len(files) > 1:
            log.info("%s: %d segments (%s)", p, len(files), ", ".join(f.name for f in files))
        rec = cls(p, message_count=total, segments=files)
        rec.read_metadata()
        return rec

    def read_metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records of the first segment before its first message (the recorder
        writes them first)."""
        for _ in self._records(self.segments[0], stop_at_first_message=True):
            pass
        return self.metadata

    def messages(self) -> Iterator[Recorded]:
        """Every message in file order (the order the recorder received them), segment after
        segment."""
        for path in self.segments:
            yield from self._messages(path)

    def _messages(self, path: Path) -> Iterator[Recorded]:
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        for record in self._records(path):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                ch = channels.get(record.channel_id)
                if ch is None:
                    raise RecordingError(f"{path}: message on unknown channel")
                sc = schemas.get(ch.schema_id)
                yield Recorded(
                    topic=ch.topic,
                    log_time_ns=record.log_time,
                    publish_time_ns=record.publish_time,
                    sequence=record.sequence,
                    encoding=ch.message_encoding,
                    schema_name=sc.name if sc is not None else "",
                    origin=ch.metadata.get("origin", "bus"),
                    data=record.data,
                )

    def _records(self, path: Path, stop_at_first_message: bool = False) -> Iterator[object]:
        first = path == self.segments[0]
        try:
            with open(path, "rb") as f:
                reader = StreamReader(f, validate_crcs=True)
                it = reader.records
                while True:
                    try:
                        record = next(it)
                    except StopIteration:
                        return
                    except Exception as exc:  # any parser error of a foreign file: judged below
                        if _at_end(f):
                            self._mark_truncated(path, exc)
                            return
                        raise RecordingError(f"{path}: damaged recording: {exc}") from None
                    if isinstance(record, Metadata) and first:
                        self.metadata[record.name] = dict(record.metadata)
                    elif isinstance(record, Message) and stop_at_first_message:
                        return
                    yield record
        except OSError as exc:
            raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from None

    def _mark_truncated(self, path: Path, exc: Exception) -> None:
        if not self.truncated:
            log.warning(
                "%s ends without its summary (recorder killed?): read up to the last complete "
                "chunk (%s)",
                path,
                type(exc).__name__,
            )
        self.truncated = True

    def gaps(self) -> list[SegmentGap]:
        """The gaps restarted recorders recorded between segments."""
        return [gap_from_json(r.data) for r in self.messages() if r.topic == sch.GAPS_TOPIC]


@dataclass(frozen=True)
class SegmentEnd:
    """The last things a (possibly killed) segment holds, for the next segment's gap record."""

    messages: int
    truncated: bool
    last_log_time_ns: int | None
    last_tick: int | None
    last_sim_time_s: float | None


def segment_end(path: Path) -> SegmentEnd:
    """Read one segment to its end (to its last complete chunk when it was cut short)."""
    recording = Recording(path, segments=[path])
    count = 0
    last_ns: int | None = None
    last_tick: Recorded | None = None
    tick_schema = sch.schema_name(SimTick)
    for rec in recording.messages():
        count += 1
        if rec.origin == sch.FOXGLOVE_ORIGIN:
            continue  # stamped in simulation time, not when received
        last_ns = rec.log_time_ns if last_ns is None else max(last_ns, rec.log_time_ns)
        if rec.schema_name == tick_schema and rec.is_bus_message:
            last_tick = rec
    tick = last_tick.message() if last_tick is not None else None
    return SegmentEnd(
        messages=count,
        truncated=recording.truncated,
        last_log_time_ns=last_ns,
        last_tick=tick.tick if isinstance(tick, SimTick) else None,
        last_sim_time_s=tick.sim_time_s if isinstance(tick, SimTick) else None,
    )


def _check_mcap(path: Path) -> int | None:
    """The message count of ``path``'s summary (None without one); raises for a non-MCAP."""
    if path.is_dir():
        raise RecordingError(f"{path}: is a directory, not a recording")
    try:
        with open(path, "rb") as f:
            if f.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                raise RecordingError(f"{path}: not an MCAP file")
            return _summary_count(f)
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read: {exc.strerror or exc}") from None


def _at_end(f: IO[bytes]) -> bool:
    """True when a read error happened because the file simply ended (truncated, not corrupt)."""
    pos = f.tell()
    return pos >= f.seek(0, 2)


def _summary_count(f: IO[bytes]) -> int | None:
    try:
        f.seek(0)
        summary = make_reader(f).get_summary()
    except (McapError, EOFError, struct.error, ValueError):
        return None
    if summary is None or summary.statistics is None:
        return None
    return int(summary.statistics.message_count)
