"""The MCAP file a recorder writes: schemas and channels registered on first use, chunks closed
often enough that a killed recorder leaves everything but the last second readable.

Used from one thread only (the recorder's writer thread).
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections import Counter
from pathlib import Path
from typing import IO

import msgspec
from mcap.writer import CompressionType, Writer

from recorder import schema as sch
from recorder.foxglove.channels import (
    Out,
    channel_schema,
    encode,
)
from recorder.reader import Recorded
from swarmbus.node import package_version

log = logging.getLogger(__name__)

# The recorder's own channels and their message types.
_OWN_TYPES: dict[str, type] = {sch.EVENTS_TOPIC: sch.RecorderEvent, sch.GAPS_TOPIC: sch.SegmentGap}

DEFAULT_CHUNK_INTERVAL_S = 1.0
DEFAULT_CHUNK_BYTES = 1 << 20


class McapSink:
    """Writes bus payloads (MessagePack) to an MCAP file as JSON messages, one channel per key."""

    def __init__(
        self,
        path: Path,
        *,
        chunk_interval_s: float = DEFAULT_CHUNK_INTERVAL_S,
        chunk_bytes: int = DEFAULT_CHUNK_BYTES,
        metadata: dict[str, str] | None = None,
    ) -> None:
        self.path = path
        self._file: IO[bytes] = open(path, "wb")  # noqa: SIM115 - closed in close()
        # Chunks are closed by us (time or size), never by the library, so that every closed
        # chunk is also flushed to the OS at once.
        self._writer = Writer(self._file, chunk_size=1 << 40, compression=CompressionType.ZSTD)
        self._writer.start(profile=sch.PROFILE, library=f"plumeswarm {package_version()}")
        self._schemas: dict[type, int] = {}
        self._foxglove_schemas: dict[str, int] = {}
        self._channels: dict[tuple[str, str], int] = {}
        self._sequence: Counter[str] = Counter()
        self.written: Counter[str] = Counter()  # per key, typed and raw
        self.undecodable: Counter[str] = Counter()
        self._chunk_interval_s = chunk_interval_s
        self._chunk_bytes = chunk_bytes
        self._pending_bytes = 0
        self._chunk_started = time.monotonic()
        self._closed = False
        if metadata:
            self._writer.add_metadata("plumeswarm", metadata)
        self._file.flush()  # the header is in the file at once (or OSError: no room)

    # -- registration ---------------------------------------------------------------------
    def _schema_id(self, type_: type) -> int:
        sid = self._schemas.get(type_)
        if sid is None:
            sid = self._writer.register_schema(
                name=sch.schema_name(type_),
                encoding=sch.SCHEMA_ENCODING,
                data=sch.json_schema(type_),
            )
            self._schemas[type_] = sid
        return sid

    def _channel_id(self, topic: str, encoding: str, type_: type | None, origin: str) -> int:
        cid = self._channels.get((topic, encoding))
        if cid is None:
            sid = self._schema_id(type_) if type_ is not None else 0
            cid = self._writer.register_channel(
                topic=topic, message_encoding=encoding, schema_id=sid, metadata={"origin": origin}
            )
            self._channels[(topic, encoding)] = cid
        return cid

    # -- writing ---------------------------------------------------------------------------
    def _add(self, cid: int, topic: str, data: bytes, log_time_ns: int, publish_ns: int) -> None:
        self._sequence[topic] += 1
        self._writer.add_message(
            channel_id=cid,
            log_time=log_time_ns,
            publish_time=publish_ns,
            sequence=self._sequence[topic] & 0xFFFFFFFF,
            data=data,
        )
        self.written[topic] += 1
        self._pending_bytes += len(data)

    def write_bus(
        self, key: str, payload: bytes, log_time_ns: int, publish_time_ns: int | None = None
    ) -> msgspec.Struct | None:
        """Store one bus payload; returns the decoded message, or None if it was kept raw."""
        publish_ns = publish_time_ns if publish_time_ns is not None else log_time_ns
        try:
            message = sch.decode_bus(payload)
        except (msgspec.DecodeError, msgspec.ValidationError, TypeError, ValueError):
            self._write_raw(key, payload, log_time_ns, publish_ns)
            return None
        cid = self._channel_id(key, sch.MESSAGE_ENCODING, type(message), "bus")
        self._add(cid, key, sch.to_json(message), log_time_ns, publish_ns)
        return message

    def _write_raw(self, key: str, payload: bytes, log_time_ns: int, publish_ns: int) -> None:
        try:
            msgspec.msgpack.decode(payload)
            encoding = sch.RAW_MSGPACK_ENCODING
        except (msgspec.DecodeError, ValueError):
            encoding = sch.RAW_BYTES_ENCODING
        if not self.undecodable[key]:
            log.warning("%s: payload is not a valid message; keeping it raw (%s)", key, encoding)
            self.write_event(
                sch.RecorderEvent(
                    kind=sch.EventKind.UNDECODABLE, key=key, detail=f"kept raw as {encoding}"
                ),
                log_time_ns,
            )
        self.undecodable[key] += 1
        cid = self._channel_id(key, encoding, None, "bus")
        self._add(cid, key, payload, log_time_ns, publish_ns)

    def write_reply(self, key: str, message: msgspec.Struct, log_time_ns: int) -> None:
        """Store the reply of a query the recorder made itself (e.g. ``plume/info``)."""
        cid = self._channel_id(key, sch.MESSAGE_ENCODING, type(message), "query-reply")
        self._add(cid, key, sch.to_json(message), log_time_ns, log_time_ns)

    def write_event(self, event: sch.RecorderEvent, log_time_ns: int | None = None) -> None:
        now = log_time_ns if log_time_ns is not None else time.time_ns()
        cid = self._channel_id(
            sch.EVENTS_TOPIC, sch.MESSAGE_ENCODING, sch.RecorderEvent, "recorder"
        )
        self._add(cid, sch.EVENTS_TOPIC, msgspec.json.encode(event), now, now)

    def write_gap(self, gap: sch.SegmentGap, log_time_ns: int | None = None) -> None:
        now = log_time_ns if log_time_ns is not None else time.time_ns()
        cid = self._channel_id(sch.GAPS_TOPIC, sch.MESSAGE_ENCODING, sch.SegmentGap, "recorder")
        self._add(cid, sch.GAPS_TOPIC, msgspec.json.encode(gap), now, now)

    def write_recorded(self, rec: Recorded) -> msgspec.Struct | None:
        """Copy one message of another recording (its channel, encoding, times); returns the
        typed bus message, None for anything else."""
        if rec.is_bus_message:
            message = rec.message()
            assert message is not None
            cid = self._channel_id(rec.topic, rec.encoding, type(message), rec.origin)
            self._add(cid, rec.topic, rec.data, rec.log_time_ns, rec.publish_time_ns)
            return message
        own = _OWN_TYPES.get(rec.topic) if rec.encoding == sch.MESSAGE_ENCODING else None
        cid = self._channel_id(rec.topic, rec.encoding, own, rec.origin)
        self._add(cid, rec.topic, rec.data, rec.log_time_ns, rec.publish_time_ns)
        return None

    def write_foxglove(self, out: Out) -> None:
        """Store one Foxglove message (:mod:`recorder.foxglove.scene`) on its channel, with the
        schema the foxglove SDK declares; log and publish time are its simulation time."""
        cs = channel_schema(type(out.message))
        cid = self._channels.get((out.topic, cs.message_encoding))
        if cid is None:
            sid = self._foxglove_schemas.get(cs.name)
            if sid is None:
                sid = self._writer.register_schema(name=cs.name, encoding=cs.encoding, data=cs.data)
                self._foxglove_schemas[cs.name] = sid
            cid = self._writer.register_channel(
                topic=out.topic,
                message_encoding=cs.message_encoding,
                schema_id=sid,
                metadata={"origin": sch.FOXGLOVE_ORIGIN},
            )
            self._channels[(out.topic, cs.message_encoding)] = cid
        self._add(cid, out.topic, encode(out.message), out.log_time_ns, out.log_time_ns)

    def maybe_close_chunk(self, now_monotonic: float | None = None) -> bool:
        """Close the open chunk (and flush it to the OS) when it is old or big enough."""
        now = now_monotonic if now_monotonic is not None else time.monotonic()
        if self._pending_bytes == 0:
            self._chunk_started = now
            return False
        if (
            self._pending_bytes < self._chunk_bytes
            and now - self._chunk_started < self._chunk_interval_s
        ):
            return False
        self._writer.flush()  # type: ignore[no-untyped-call]
        self._pending_bytes = 0
        self._chunk_started = now
        return True

    def abandon(self) -> None:
        """Close the file after a write error without its summary: it ends after its last
        complete chunk, as a killed recorder's segment does."""
        self._closed = True
        with contextlib.suppress(OSError):
            self._file.close()

    def close(self, summary: dict[str, str] | None = None) -> None:
        """Write the summary (indexes, statistics) and close the file."""
        if self._closed:
            return
        self._closed = True
        if summary:
            self._writer.add_metadata("plumeswarm.summary", summary)
        self._writer.finish()  # type: ignore[no-untyped-call]
        self._file.close()
