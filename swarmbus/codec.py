"""The one encoding of the bus: MessagePack via msgspec, typed decoding with clear errors.

MessagePack because it is compact and fast for the many small numeric messages of the lockstep,
and msgspec validates while it decodes (types, bounds, schema tag) in one pass.
"""

from __future__ import annotations

import logging
import re
from functools import cache
from typing import Any, TypeVar

import msgspec

from swarmbus.errors import FieldError

T = TypeVar("T")

_encoder = msgspec.msgpack.Encoder()
_PATH_RE = re.compile(r" - at `\$(?P<path>[^`]*)`$")


class MessageError(FieldError):
    """A payload that is not a valid message: names the field (``$``-path) and the reason."""

    def __init__(self, type_name: str, field: str, reason: str) -> None:
        self.type_name = type_name
        super().__init__(f"invalid {type_name}", field, reason, blank="<payload>")


def encode(message: Any) -> bytes:
    """Encode a message struct to bytes."""
    return _encoder.encode(message)


def split_validation_error(exc: msgspec.ValidationError) -> tuple[str, str]:
    """``(field, reason)`` of a msgspec error: the ``$``-path without ``$.``, and the message."""
    text = str(exc)
    m = _PATH_RE.search(text)
    if m is None:
        return "", text
    return m.group("path").lstrip("."), text[: m.start()]


@cache
def _decoder(type_: Any) -> msgspec.msgpack.Decoder[Any]:
    return msgspec.msgpack.Decoder(type_)


def _type_name(type_: Any) -> str:
    return getattr(type_, "__name__", None) or str(type_)


def decode(data: bytes | bytearray | memoryview, type_: type[T]) -> T:
    """Decode ``data`` as ``type_`` (a struct or a union of structs).

    Raises :class:`MessageError` for anything else: garbage, wrong type, missing field,
    out-of-range or non-finite number, wrong schema version.
    """
    try:
        return _decoder(type_).decode(data)  # type: ignore[no-any-return,arg-type]
    except msgspec.ValidationError as exc:
        field, reason = split_validation_error(exc)
        raise MessageError(_type_name(type_), field, reason) from None
    except msgspec.DecodeError as exc:
        raise MessageError(_type_name(type_), "", f"malformed payload: {exc}") from None
    except (TypeError, ValueError) as exc:  # __post_init__ checks
        raise MessageError(_type_name(type_), "", str(exc)) from None


def decode_or_none(
    data: bytes | bytearray | memoryview, type_: type[T], what: object, log: logging.Logger
) -> T | None:
    """``data`` decoded as ``type_``, or None after one warning on ``log``, ``ignoring <what>:
    <why>``: how a process drops a message that does not decode and goes on."""
    try:
        return decode(data, type_)
    except MessageError as exc:
        log.warning("ignoring %s: %s", what, exc)
        return None
