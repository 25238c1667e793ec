"""Request/reply on the bus: one way to ask a queryable (:func:`request`, :func:`ask`) and one way
to serve one (:func:`serve`, :func:`serve_later`); a request ends in a reply, a refusal
(:class:`Refused`), no reply (:class:`NoReply`) or a bad reply (:class:`BadReply`). See
docs/bus.md ("Request and reply").
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from typing import Any, Generic, TypeVar

import zenoh

from swarmbus.codec import MessageError, decode, encode
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import CommandReply, ErrorReply, RejectCode
from swarmbus.session import message_limit, payload_or_none

log = logging.getLogger(__name__)

Q = TypeVar("Q")
R = TypeVar("R")
MAX_REASON_CHARS = 1000  # ErrorReply.reason's bound
# How much longer than its timeout a caller waits for Zenoh to finalise a query (its own
# timeout ends the query; this only bounds a wait that Zenoh would never end).
FINALISE_MARGIN_S = 5.0


class RequestError(PlumeswarmError):
    """A request that got no usable reply; ``key`` is where it was sent."""

    def __init__(self, key: str, message: str) -> None:
        self.key = key
        super().__init__(message)


class Refused(RequestError, ValueError):
    """A refusal: ``field`` of the request (``""``: the request as a whole) and ``reason``.

    Raised by :func:`request` when the server refused; raised by a handler of :func:`serve` to
    refuse (it becomes the ``ErrorReply``)."""

    def __init__(self, field: str, reason: str, key: str = "") -> None:
        self.field = field
        self.reason = reason
        where = f"{key}: " if key else ""
        super().__init__(key, f"{where}refused: {field or '<request>'}: {reason}")


class NoReply(RequestError, TimeoutError):
    """Nobody answered ``key`` within ``timeout_s`` (``detail``: what Zenoh said, if anything)."""

    def __init__(self, key: str, timeout_s: float, detail: str = "") -> None:
        self.timeout_s = timeout_s
        self.detail = detail
        why = f" ({detail})" if detail else ""
        super().__init__(key, f"no reply on {key} within {timeout_s:g} s{why}")


class BadReply(RequestError):
    """A reply that does not decode as the expected type: ``field`` and ``reason``."""

    def __init__(self, key: str, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(key, f"bad reply on {key}: {field or '<payload>'}: {reason}")


# ------------------------------------------------------------------------------ clients
class Pending(Generic[R]):
    """A request in flight (from :func:`ask`). Its outcome is the first reply, decoded, or a
    :class:`RequestError`; it is settled once, when that reply or the timeout comes.

    With an ``on_done`` callback Zenoh delivers the reply to it on a thread of its own; without
    one the reply waits in Zenoh's channel until :meth:`outcome` or :meth:`done` reads it (no
    hand-over between threads: a blocking round trip costs what a plain ``session.get`` does)."""

    def __init__(
        self,
        key: str,
        reply_type: type[R],
        timeout_s: float,
        on_done: Callable[[R | RequestError], None] | None = None,
    ) -> None:
        self.key = key
        self.timeout_s = timeout_s
        self._reply_type = reply_type
        self._on_done = on_done
        self._lock = threading.Lock()
        self._settled = threading.Event()
        self._outcome: R | RequestError | None = None
        self.answered = False  # a reply came (Zenoh's own error replies count), not only the end
        self.replies: zenoh.Handler[zenoh.Reply] | None = None  # without on_done: read here

    def done(self) -> bool:
        """Whether the outcome is known (never blocks)."""
        if self.replies is not None and not self._settled.is_set():
            try:
                reply = self.replies.try_recv()
            except zenoh.ZError:  # the query ended without a reply
                self.on_finish()
            else:
                if reply is not None:
                    self.on_reply(reply)
        return self._settled.is_set()

    def outcome(self) -> R | RequestError:
        """The reply or the error, waiting for it (at most the request's timeout, and a margin)."""
        if self.replies is not None and not self._settled.is_set():
            try:
                for reply in self.replies:  # the first reply, or the end of the query
                    self.on_reply(reply)
                    break
            except zenoh.ZError as exc:  # the session closed under the query
                self.on_failure(str(exc))
            self.on_finish()
        if not self._settled.wait(self.timeout_s + FINALISE_MARGIN_S):
            self._settle(NoReply(self.key, self.timeout_s, "the query never ended"))
        assert self._outcome is not None
        return self._outcome

    def result(self) -> R:
        """The reply (waiting for it); raises :class:`Refused`, :class:`NoReply` or
        :class:`BadReply`."""
        outcome = self.outcome()
        if isinstance(outcome, RequestError):
            raise outcome
        return outcome

    # Where the reply and the end of the query arrive (a Zenoh thread, or the channel's reader)
    def on_reply(self, reply: zenoh.Reply) -> None:
        if not self._settled.is_set():
            self.answered = True
            self._settle(self._read(reply))

    def on_finish(self) -> None:
        self._settle(NoReply(self.key, self.timeout_s))

    def on_failure(self, detail: str) -> None:
        """The query could not be sent (e.g. the session is closed)."""
        self._settle(NoReply(self.key, self.timeout_s, f"query failed: {detail}"))

    def _read(self, reply: zenoh.Reply) -> R | RequestError:
        if reply.ok is not None:
            data = payload_or_none(reply.ok, "a reply", log)
            if data is None:
                limit = f"over [network] max_message_size_bytes {message_limit()}"
                return BadReply(self.key, "", f"{len(reply.ok.payload)} bytes, {limit}")
            try:
                return decode(data, self._reply_type)
            except MessageError as exc:
                return BadReply(self.key, exc.field, exc.reason)
        data = reply.err.payload.to_bytes() if reply.err is not None else b""
        try:
            err = decode(data, ErrorReply)
        except MessageError:  # Zenoh's own, e.g. "Timeout"
            return NoReply(self.key, self.timeout_s, data[:200].decode("utf-8", "replace"))
        return Refused(err.field, err.reason, self.key)

    def _settle(self, outcome: R | RequestError) -> None:
        with self._lock:
            if self._settled.is_set():
                return
            self._outcome = outcome
            self._settled.set()
        if self._on_done is not None:
            try:
                self._on_done(outcome)
            except Exception:
                log.exception("%s: reply callback failed", self.key)


def ask(
    session: zenoh.Session,
    key: str,
    message: Any,
    reply_type: type[R],
    timeout_s: float,
    on_done: Callable[[R | RequestError], None] | None = None,
) -> Pending[R]:
    """Send ``message`` (a message struct, or its encoding) to the queryable on ``key`` without
    waiting. ``on_done`` (optional) gets the outcome once, on a Zenoh thread: keep it short."""
    pending = Pending(key, reply_type, timeout_s, on_done)
    payload = message if isinstance(message, bytes) else encode(message)
    try:
        if on_done is None:
            pending.replies = session.get(key, payload=payload, timeout=timeout_s)
        else:
            handler = zenoh.handlers.Callback(pending.on_reply, pending.on_finish)
            session.get(key, handler, payload=payload, timeout=timeout_s)
    except zenoh.ZError as exc:
        pending.on_failure(str(exc))
    return pending


def request(
    session: zenoh.Session, key: str, message: Any, reply_type: type[R], timeout_s: float
) -> R:
    """Send ``message`` to the queryable on ``key`` and return its reply as ``reply_type``.

    Raises :class:`Refused` (the server answered with an ``ErrorReply``: ``.field``,
    ``.reason``), :class:`NoReply` (nobody answered within ``timeout_s``) or
    :class:`BadReply`."""
    return ask(session, key, message, reply_type, timeout_s).result()


# ------------------------------------------------------------------------------ servers
class Incoming(Generic[Q]):
    """A decoded request to answer once (:meth:`reply`, :meth:`refuse` or :meth:`answer`),
    now or later, from any thread."""

    def __init__(self, query: zenoh.Query, request: Q, key: str) -> None:
        self.request = request
        self.key = key
        self._query: zenoh.Query | None = query

    def reply(self, message: Any) -> bytes:
        """Answer with ``message`` (a struct); returns its encoding."""
        payload = encode(message)
        query = self._take()
        if query is not None:
            query.reply(query.key_expr, payload)
            query.drop()
        return payload

    def refuse(self, field: str, reason: str) -> None:
        """Answer with ``ErrorReply(field, reason)``."""
        log.warning("%s: refused: %s: %s", self.key, field or "<request>", reason)
        _refuse(self._take(), field, reason)

    def answer(self, handler: Callable[[Q], Any]) -> bytes | None:
        """Answer with ``handler(request)``, or refuse when it raises a ``ValueError``; returns
        the reply's encoding (None when refused or failed: a failure is logged, unanswered)."""
        try:
            result = handler(self.request)
        except ValueError as exc:
            field, reason = _field_and_reason(exc)
            self.refuse(field, reason)
            return None
        except Exception:  # the server outlives any one request
            log.exception("%s: handling a request failed", self.key)
            self.drop()
            return None
        return self.reply(result)

    def drop(self) -> None:
        """Give up without an answer (the client sees no reply)."""
        query = self._take()
        if query is not None:
            query.drop()

    def _take(self) -> zenoh.Query | None:
        query, self._query = self._query, None
        return query


def _field_and_reason(exc: ValueError) -> tuple[str, str]:
    if isinstance(exc, (Refused, MessageError)):
        return exc.field, exc.reason
    return "", str(exc)


def _refuse(query: zenoh.Query | None, field: str, reason: str) -> None:
    if query is not None:
        err = ErrorReply(field=field, reason=reason[:MAX_REASON_CHARS])
        query.reply_err(encode(err))
        query.drop()


def _payload(query: zenoh.Query) -> bytes | None:
    """The query's payload, or None (refused with an ``ErrorReply``, logged) when it is over
    ``[network] max_message_size_bytes``."""
    data = payload_or_none(query, "a request", log)
    if data is None:
        _refuse(query, "", f"over [network] max_message_size_bytes {message_limit()}")
    return data


def _accept(query: zenoh.Query, data: bytes, key: str, request_type: type[Q]) -> Incoming[Q] | None:
    """The query's request (``data``) decoded, or None when it was refused for not decoding."""
    try:
        request = decode(data, request_type)
    except MessageError as exc:
        log.warning("%s: refused: %s", key, exc)
        _refuse(query, exc.field, exc.reason)
        return None
    return Incoming(query, request, key)


def serve(
    session: zenoh.Session,
    key: str,
    request_type: type[Q],
    handler: Callable[[Q], Any],
    *,
    memo: bool = False,
) -> zenoh.Queryable[None]:
    """Declare the queryable on ``key``: each request decoded as ``request_type``, answered
    with ``handler(request)`` (a message struct), refused with an ``ErrorReply`` naming the
    field when it does not decode or the handler raises a ``ValueError``. The handler runs on
    Zenoh's thread. ``memo``: a request equal (byte for byte) to the previous one gets the
    previous reply without calling the handler (a lockstep's processes ask the same)."""
    last: list[tuple[bytes, bytes]] = []  # at most one (request, reply); replaced atomically

    def on_query(query: zenoh.Query) -> None:
        data = _payload(query)
        if data is None:
            return
        if memo and last and last[0][0] == data:
            query.reply(query.key_expr, last[0][1])
            query.drop()
            return
        incoming = _accept(query, data, key, request_type)
        if incoming is None:
            return
        out = incoming.answer(handler)
        if memo and out is not None:
            last[:] = [(data, out)]

    return session.declare_queryable(key, on_query)


def serve_later(
    session: zenoh.Session,
    key: str,
    request_type: type[Q],
    on_request: Callable[[Incoming[Q]], None],
) -> zenoh.Queryable[None]:
    """Declare the queryable on ``key`` for a server that answers later or elsewhere: each
    request is decoded (refused with an ``ErrorReply`` when it does not) and handed to
    ``on_request`` (on Zenoh's thread) as an :class:`Incoming` to answer once."""

    def on_query(query: zenoh.Query) -> None:
        data = _payload(query)
        incoming = None if data is None else _accept(query, data, key, request_type)
        if incoming is not None:
            on_request(incoming)

    return session.declare_queryable(key, on_query)


# ------------------------------------------------------------------------------ commands
def command_reply(vehicle_id: str, outcome: CommandReply | RequestError) -> CommandReply:
    """A command's outcome as a ``CommandReply``, for clients that report a result code rather
    than raise (the gateway's MAVLink results, the environments): a refusal is
    ``RejectCode.INVALID`` with the field and the reason, no reply or a bad reply
    ``RejectCode.FAILED``."""
    if isinstance(outcome, CommandReply):
        return outcome
    if isinstance(outcome, Refused):
        code, reason = RejectCode.INVALID, f"{outcome.field}: {outcome.reason}"
    elif isinstance(outcome, NoReply):
        detail = f" ({outcome.detail})" if outcome.detail else ""
        code, reason = RejectCode.FAILED, f"no reply from the autopilot{detail}"
    else:
        code, reason = RejectCode.FAILED, str(outcome)
    return CommandReply(
        vehicle_id=vehicle_id, accepted=False, code=code, reason=reason[:MAX_REASON_CHARS]
    )
