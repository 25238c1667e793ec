"""How bus messages are stored in MCAP: JSON messages described by JSON Schemas.

The bus speaks MessagePack, for which MCAP's registry defines no schema language; JSON with a
``jsonschema`` schema per message type is what Foxglove, ``mcap cat --json`` and any JSON tool
read without help. Messages are transcoded losslessly (msgspec writes floats shortest-round-trip;
``bytes`` fields become base64 strings, as the schema says), and :func:`from_json` turns them back
into the same typed structs. Payloads that are not a valid message of this version are kept
verbatim on a separate channel (``msgpack`` or ``application/octet-stream``), never dropped.
"""

from __future__ import annotations

import enum
from functools import cache
from typing import Any, Union

import msgspec

from swarmbus.messages import ALL_MESSAGES, Message

SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "json"
RAW_MSGPACK_ENCODING = "msgpack"
RAW_BYTES_ENCODING = "application/octet-stream"
SCHEMA_PREFIX = "plumeswarm."
EVENTS_TOPIC = "recorder/events"  # an MCAP topic, not a bus key (replay never publishes it)
GAPS_TOPIC = "recorder/gaps"  # a restarted recorder's gap between segments (its own channel)
PROFILE = "plumeswarm"
FOXGLOVE_ORIGIN = "foxglove"  # channel metadata ``origin`` of the Foxglove channels

# msgspec decodes a tagged union of every message in one pass (the ``schema`` field picks).
AnyMessage: Any = Union[ALL_MESSAGES]  # noqa: UP007 - a runtime union of a tuple of types

_msgpack_decoder = msgspec.msgpack.Decoder(AnyMessage)
_json_decoder = msgspec.json.Decoder(AnyMessage)
_json_encoder = msgspec.json.Encoder()


class EventKind(enum.StrEnum):
    STARTED = "started"
    BEHIND = "behind"  # the write queue is falling behind the bus
    CAUGHT_UP = "caught_up"
    DROPPED = "dropped"  # the queue hit its hard limit: messages were lost (counted)
    UNDECODABLE = "undecodable"  # a payload that is not a valid message (kept raw)
    GAP = "gap"  # ticks missing from a per-tick stream: lost before reaching the recorder
    STOPPED = "stopped"
    RESUMED = "resumed"  # a restarted recorder continues in a new segment (see SegmentGap)
    WRITE_ERROR = "write_error"  # the disk refused a write (full, I/O error): segment abandoned
    CLOCK = "clock"  # a publisher's clock differs from the recorder's by more than Zenoh's bound


class RecorderEvent(msgspec.Struct, frozen=True, kw_only=True):
    """A line of the recorder's own log, on the ``recorder/events`` channel."""

    kind: EventKind
    detail: str = ""
    key: str = ""
    backlog: int = 0
    dropped: int = 0
    received: int = 0
    written: int = 0
    lost_upstream: int = 0  # total messages missing from per-tick streams so far


class SegmentGap(msgspec.Struct, frozen=True, kw_only=True):
    """What a restarted recorder, or one going on after a write error, did not record: between
    the end of the previous segment (what was flushed to it before the old recorder died or the
    disk refused a write) and the first messages of this one. On the ``recorder/gaps`` channel
    of the new segment. Times are the recorder's receive times (log time, ns since the epoch);
    ticks and sim times are those of ``sim/tick``. ``None``: unknown (no such message in that
    segment)."""

    previous_segment: str  # file name, next to this one
    previous_truncated: bool  # the previous segment ends without its summary (killed)
    previous_messages: int
    previous_last_log_time_ns: int | None
    previous_last_tick: int | None
    previous_last_sim_time_s: float | None
    first_log_time_ns: int | None  # the first bus message of this segment
    first_tick: int | None
    first_sim_time_s: float | None
    gap_s: float | None  # wall seconds between the two log times
    ticks_missing: int | None  # first_tick - previous_last_tick - 1
    reason: str = ""  # why the previous segment ended ("": its recorder was restarted)


def gap_from_json(data: bytes) -> SegmentGap:
    return msgspec.json.decode(data, type=SegmentGap)


def decode_bus(payload: bytes) -> Message:
    """A bus payload (MessagePack) as its typed message; raises msgspec errors."""
    return _msgpack_decoder.decode(payload)  # type: ignore[no-any-return]


def to_json(message: msgspec.Struct) -> bytes:
    return _json_encoder.encode(message)


def from_json(data: bytes) -> Message:
    """A stored message back as its typed struct; raises msgspec errors."""
    return _json_decoder.decode(data)  # type: ignore[no-any-return]


def event_from_json(data: bytes) -> RecorderEvent:
    return msgspec.json.decode(data, type=RecorderEvent)


def schema_name(type_: type) -> str:
    return SCHEMA_PREFIX + type_.__name__


def _inline_refs(node: Any, defs: dict[str, Any]) -> Any:
    # Several viewers do not follow "$ref"; our messages are not recursive, so inline them.
    if isinstance(node, dict):
        ref = node.get("$ref")
        if isinstance(ref, str) and ref.startswith("#/$defs/"):
            return _inline_refs(defs[ref.removeprefix("#/$defs/")], defs)
        return {k: _inline_refs(v, defs) for k, v in node.items()}
    if isinstance(node, list):
        return [_inline_refs(v, defs) for v in node]
    return node


@cache
def json_schema(type_: type) -> bytes:
    """The JSON Schema of ``type_`` with every ``$ref`` inlined (one self-contained object)."""
    raw = msgspec.json.schema(type_)
    defs = raw.get("$defs", {})
    inlined = _inline_refs({k: v for k, v in raw.items() if k != "$defs"}, defs)
    return msgspec.json.encode(inlined)
