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

from deploy.recording import schema as sch
from swarmbus.messages import Message as BusMessage

log = logging.getLogger(__name__)

MCAP_MAGIC = b"\x89MCAP0\r\n"


class RecordingError(RuntimeError):
    """A recording that cannot be read: missing, not MCAP, or damaged."""


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
    """A recording file; iterate :meth:`messages` (once or many times)."""

    path: Path
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    truncated: bool = False
    message_count: int | None = None  # from the summary, when the file has one

    @classmethod
    def open(cls, path: str | Path) -> Recording:
        p = Path(path)
        if not p.exists():
            raise RecordingError(f"{p}: no such file")
        if p.is_dir():
            raise RecordingError(f"{p}: is a directory, not a recording")
        try:
            with open(p, "rb") as f:
                magic = f.read(len(MCAP_MAGIC))
                if magic != MCAP_MAGIC:
                    raise RecordingError(f"{p}: not an MCAP file")
                count = _summary_count(f)
        except OSError as exc:
            raise RecordingError(f"{p}: cannot read: {exc.strerror or exc}") from None
        rec = cls(p, message_count=count)
        rec.read_metadata()
        return rec

    def read_metadata(self) -> dict[str, dict[str, str]]:
        """Metadata records before the first message (the recorder writes them first)."""
        for _ in self._records(stop_at_first_message=True):
            pass
        return self.metadata

    def messages(self) -> Iterator[Recorded]:
        """Every message in file order (the order the recorder received them)."""
        channels: dict[int, Channel] = {}
        schemas: dict[int, Schema] = {}
        for record in self._records():
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Message):
                ch = channels.get(record.channel_id)
                if ch is None:
                    raise RecordingError(f"{self.path}: message on unknown channel")
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

    def _records(self, stop_at_first_message: bool = False) -> Iterator[object]:
        try:
            with open(self.path, "rb") as f:
                reader = StreamReader(f, validate_crcs=True)
                it = reader.records
                while True:
                    try:
                        record = next(it)
                    except StopIteration:
                        return
                    except Exception as exc:  # any parser error of a foreign file: judged below
                        if _at_end(f):
                            self._mark_truncated(exc)
                            return
                        raise RecordingError(f"{self.path}: damaged recording: {exc}") from None
                    if isinstance(record, Metadata):
                        self.metadata[record.name] = dict(record.metadata)
                    elif isinstance(record, Message) and stop_at_first_message:
                        return
                    yield record
        except OSError as exc:
            raise RecordingError(f"{self.path}: cannot read: {exc.strerror or exc}") from None

    def _mark_truncated(self, exc: Exception) -> None:
        if not self.truncated:
            log.warning(
                "%s ends without its summary (recorder killed?): read up to the last complete "
                "chunk (%s)",
                self.path,
                type(exc).__name__,
            )
        self.truncated = True


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
