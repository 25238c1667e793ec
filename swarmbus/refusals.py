"""What Zenoh's access-control list refuses, made visible: one warning line per refused message,
naming the key, what was refused and the identity (the certificate's common name) that sent it.

Zenoh drops a message its ACL refuses where it arrives and says so only in its trace of the ACL
interceptor (``zenoh::net::routing::interceptor``), written to the process's standard output.
:func:`watch` turns that trace on for this process, reads it through a pipe, keeps the refusals
(a decision "is unauthorized" followed on the same thread by "Msg intercepted!") and forwards
every other line to the real standard output. The warnings are rate-limited so that a flood
cannot fill a disk: the first refusal of each (identity, action, key) is logged at once, later
ones as one line per :data:`REPEAT_S` with their count, and at most :data:`BURST` lines at once
then one a second (a count of the lines held back follows). A link whose certificate names no
subject of the ACL (Zenoh logs no decision of it) gets one line, by its Zenoh id, when it
connects."""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import logging
import os
import re
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import zenoh

log = logging.getLogger(__name__)

DIRECTIVE = "zenoh::net::routing::interceptor=trace"  # the ACL's decisions and its drops
TARGET = b"zenoh::net::routing::interceptor"
DROPPED = b"Msg intercepted!"
NO_SUBJECT = b"did not match any configured ACL subject"  # a link of an unknown identity
REPEAT_S = 60.0  # a repeated refusal: one line (with its count) per this many seconds
BURST = 100  # lines at once; then one a second
MAX_TRACKED = 4096  # (identity, action, key) remembered for repeats
PIPE_BYTES = 1 << 20  # room for the trace while the reader waits for the interpreter

_ANSI = re.compile(rb"\x1b\[[0-9;]*m")
_THREAD = re.compile(rb"ThreadId\((\d+)\)")
_DECISION = re.compile(
    r"(?:Using cached result: )?(?P<zid>[0-9a-f]+)(?: on (?P<subject>\S+))? is unauthorized to "
    r"(?:Declare/Undeclare |Declare )?(?P<action>.+?) \((?P<flow>ingress|egress)\) "
    r"on (?P<key>\S+)\s*$"
)
_STRANGER = re.compile(r"([0-9a-f]+) did not match any configured ACL subject")
_SUBJECT = re.compile(r"(?P<zid>[0-9a-f]+) on (?P<subject>\S+) is (?:un)?authorized to ")
_COMMON_NAME = re.compile(r"CertCommonName\(([^)]*)\)")


@dataclass(frozen=True)
class Refusal:
    """One message the ACL dropped where it arrived."""

    identity: str  # the sender's certificate common name, else ``zenoh id <zid>``
    action: str  # put, delete, query, reply, liveliness token, ...
    key: str


def parse_refusal(decision: str, names: dict[str, str]) -> Refusal | None:
    """The ingress refusal of one trace line of the ACL (ANSI codes removed), or None;
    ``names``: zenoh id → identity, learnt from the lines that name the subject."""
    m = _DECISION.search(decision)
    if m is None or m["flow"] != "ingress":
        return None
    zid = m["zid"]
    if m["subject"]:
        names[zid] = identity_of(m["subject"])
    identity = names.get(zid, f"zenoh id {zid}")
    return Refusal(identity, m["action"].lower(), m["key"])


def identity_of(subject: str) -> str:
    """The certificate common name of an ACL subject (``Interface(lo)+CertCommonName(x)+...``),
    else the subject as Zenoh prints it."""
    m = _COMMON_NAME.search(subject)
    return m.group(1) if m and m.group(1) else subject


@dataclass
class RefusalLog:
    """Rate-limited warnings of refusals (see the module's docstring); ``clock`` in seconds."""

    repeat_s: float = REPEAT_S
    burst: int = BURST
    clock: Callable[[], float] = time.monotonic
    total: int = 0
    _last: dict[Refusal, tuple[float, int]] = field(default_factory=dict)
    _tokens: float = float(BURST)
    _refilled: float | None = None
    _held_back: int = 0

    def record(self, r: Refusal) -> list[str]:
        """Count ``r``; the lines to log now (none while rate-limited)."""
        return self._lines(r, f"access control refused {r.action} on {r.key} from {r.identity}")

    def stranger(self, zid: str) -> list[str]:
        """A link whose certificate names no identity of the ACL: the lines to log now."""
        line = (
            f"access control: zenoh id {zid} shows a certificate that names no identity of the "
            "hosts file; everything it sends is refused"
        )
        return self._lines(Refusal(f"zenoh id {zid}", "everything", "*"), line)

    def _lines(self, r: Refusal, line: str) -> list[str]:
        now = self.clock()
        self.total += 1
        if self._refilled is None:
            self._refilled = now
        self._tokens = min(float(self.burst), self._tokens + (now - self._refilled))
        self._refilled = now
        last = self._last.get(r)
        if last is not None and now - last[0] < self.repeat_s:
            self._last[r] = (last[0], last[1] + 1)
            return []
        if self._tokens < 1.0:
            self._held_back += 1
            return []
        self._tokens -= 1.0
        if last is None and len(self._last) >= MAX_TRACKED:
            self._last.clear()
        self._last[r] = (now, 0)
        if last is not None and last[1]:
            line += f" ({last[1]} more since {now - last[0]:.0f} s ago)"
        lines = [line]
        if self._held_back:
            lines.append(f"access control: {self._held_back} more refusals not logged (rate limit)")
            self._held_back = 0
        return lines


class _Reader:
    """Reads the trace from the pipe: refusals to the log, every other line to ``out``."""

    def __init__(self, fd: int, out: int, refusals: RefusalLog) -> None:
        self.fd = fd
        self.out = out
        self.refusals = refusals
        self.names: dict[str, str] = {}
        self.last_decision: dict[bytes, bytes] = {}  # thread → its newest ACL decision

    def run(self) -> None:
        rest = b""
        while chunk := os.read(self.fd, 65536):
            lines = (rest + chunk).split(b"\n")
            rest = lines.pop()
            passed = [line for line in lines if not self.take(line)]
            if passed:
                os.write(self.out, b"\n".join(passed) + b"\n")
        if rest and not self.take(rest):
            os.write(self.out, rest)

    def take(self, line: bytes) -> bool:
        """Whether ``line`` is the ACL's trace (then used here, not forwarded)."""
        if TARGET not in line:
            return False
        thread = _THREAD.search(line)
        tid = thread.group(1) if thread else b""
        if NO_SUBJECT in line:
            self.stranger(_text(line))
        elif DROPPED in line:
            decision = self.last_decision.pop(tid, b"")
            if b"is unauthorized" in decision:
                self.refused(_text(decision))
        elif b"authorized to" in line:
            self.last_decision[tid] = line
            if b" on " in line and b"CertCommonName(" in line and b"cached" not in line:
                self.learn(_text(line))
        return True

    def stranger(self, text: str) -> None:
        m = _STRANGER.search(text)
        if m:
            _warn(self.refusals.stranger(m.group(1)))

    def refused(self, decision: str) -> None:
        refusal = parse_refusal(decision, self.names)
        if refusal is not None:
            _warn(self.refusals.record(refusal))

    def learn(self, text: str) -> None:
        m = _SUBJECT.search(text)
        if m:
            self.names[m["zid"]] = identity_of(m["subject"])


def _text(line: bytes) -> str:
    return _ANSI.sub(b"", line).decode("utf-8", "replace")


def _warn(lines: list[str]) -> None:
    for line in lines:
        log.warning("%s", line)


_watching: RefusalLog | None = None
_lock = threading.Lock()


def watch() -> RefusalLog:
    """Log this process's ACL refusals (once per process, before its first session opens).
    ``RUST_LOG``, when set, replaces :data:`DIRECTIVE` (Zenoh's own logs then follow it)."""
    global _watching
    with _lock:
        if _watching is not None:
            return _watching
        sys.stdout.flush()
        saved = os.dup(1)
        read_fd, write_fd = os.pipe()
        with contextlib.suppress(OSError):  # else the default size: the trace waits sooner
            fcntl.fcntl(write_fd, fcntl.F_SETPIPE_SZ, PIPE_BYTES)
        os.dup2(write_fd, 1)
        os.close(write_fd)
        refusals = RefusalLog()
        reader = _Reader(read_fd, saved, refusals)
        thread = threading.Thread(target=reader.run, name="acl-refusals", daemon=True)
        thread.start()
        zenoh.init_log_from_env_or(DIRECTIVE)

        def restore() -> None:  # the last lines of the process reach the real output
            sys.stdout.flush()
            os.dup2(saved, 1)
            thread.join(timeout=2.0)

        atexit.register(restore)
        _watching = refusals
        return refusals
