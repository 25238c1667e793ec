"""The one encoding of the bus: MessagePack via msgspec, typed decoding with clear errors.

MessagePack because it is compact and fast for the many small numeric messages of the lockstep,
and msgspec validates while it decodes (types, bounds, schema tag) in one pass.
"""

from __future__ import annotations

import logging
import re
import threading
import time
from collections import Counter
from collections.abc import Callable
from functools import cache
from typing import Any, TypeVar

import msgspec

from swarmbus.errors import FieldError

T = TypeVar("T")

# A refused message is logged at once the first time on its key, then at most once per key
# every REFUSAL_LOG_PERIOD_S with the count refused since: a flood does not flood the log.
REFUSAL_LOG_PERIOD_S = 5.0

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


class Refusals:
    """The log of messages a process refuses (malformed, too large, not its type), rate-limited
    per key: the first refusal on a key is one warning line at once, ``ignoring <what on
    key>: <why>``; later ones on that key are counted and said in one line at most every
    ``period_s`` (``... (N more refused on <key> since)``). Thread-safe."""

    def __init__(
        self,
        log: logging.Logger,
        period_s: float = REFUSAL_LOG_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._log = log
        self._period_s = period_s
        self._clock = clock
        self._lock = threading.Lock()
        self._last: dict[tuple[str, str], float] = {}  # when a (key, kind) was last logged
        self._unsaid: Counter[tuple[str, str]] = Counter()  # refused since that line
        self.refused: Counter[str] = Counter()

    def refuse(self, key: str, what: object, why: object, kind: str = "") -> None:
        """One refused message on ``key`` (``what``: the message, as the line names it, key
        included): logged now, or counted for the next line. Refusals of different ``kind``
        on one key (a whole message, one entry of it) are rate-limited apart."""
        now = self._clock()
        slot = (key, kind)
        with self._lock:
            self.refused[key] += 1
            last = self._last.get(slot)
            if last is not None and now - last < self._period_s:
                self._unsaid[slot] += 1
                return
            self._last[slot] = now
            more = self._unsaid.pop(slot, 0)
        if more:
            self._log.warning("ignoring %s: %s (%d more refused on %s since)", what, why, more, key)
        else:
            self._log.warning("ignoring %s: %s", what, why)


_refusals: dict[str, Refusals] = {}
_refusals_lock = threading.Lock()


def refusals(log: logging.Logger) -> Refusals:
    """The one :class:`Refusals` of ``log`` (per logger, so each module's lines keep its name)."""
    with _refusals_lock:
        found = _refusals.get(log.name)
        if found is None:
            found = _refusals[log.name] = Refusals(log)
        return found


def decode_or_none(
    data: bytes | bytearray | memoryview,
    type_: type[T],
    what: object,
    log: logging.Logger,
    key: str = "",
    kind: str = "",
) -> T | None:
    """``data`` decoded as ``type_``, or None after a warning on ``log``, ``ignoring <what> on
    <key>: <why>`` (``ignoring <what>: <why>`` without a key; rate-limited per key or
    ``what``, and ``kind``, :class:`Refusals`): how a process drops a message that does not
    decode and goes on."""
    try:
        return decode(data, type_)
    except MessageError as exc:
        refusals(log).refuse(key or str(what), f"{what} on {key}" if key else what, exc, kind)
        return None
