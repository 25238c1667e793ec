"""The recorder's write-ahead spool: every message that reaches the recorder, appended to a
file (one ``write`` system call each, into the OS's page cache) before it is queued for the
MCAP writer. A recorder killed with SIGKILL loses its queue and its open chunk, not the spool:
the restarted recorder recovers from it what the killed segment does not hold.

Files: ``<segment>.spool.<generation>`` next to the segment. A record is a header
(:data:`HEADER`: key length, payload length, receive time ns, publish time ns or -1, whether
it is a query reply) followed by the key and the payload. Whenever the writer has closed a
chunk (flushed to the OS) the spool starts a new generation and deletes the generations whose
every message is in a closed chunk, so the spool holds about one chunk interval of messages.
A clean stop deletes the spool (everything is in the closed MCAP file).

The spool is in the page cache at once (a killed process loses none of it) and on the disk
within :data:`DEFAULT_FSYNC_INTERVAL_S` (``recorder.spool_fsync_s``): the recorder's writer
thread calls :meth:`Spool.sync` at that interval, so a host that loses power loses at most that
much of what the spool holds. A write that fails (disk full, I/O error) raises ``OSError``: the
recorder then abandons the segment and keeps the spool for its successor (:meth:`Spool.abandon`).
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import struct
from collections.abc import Iterator
from pathlib import Path

HEADER = struct.Struct("<IIqqB")
_MARK = struct.Struct("<qI")  # durable receive time, then the length of the ticks' JSON
_GENERATION = re.compile(r"\.spool\.(?P<n>[0-9]+)$")

# key, payload, receive time (ns), publish time (ns, the sample's timestamp), is a query reply
SpoolItem = tuple[str, bytes, int, int | None, bool]

DEFAULT_FSYNC_INTERVAL_S = 1.0


def spool_files(segment: Path) -> list[Path]:
    """The spool generations of ``segment`` that exist, oldest first."""
    found = []
    for path in segment.parent.glob(f"{segment.name}.spool.*"):
        m = _GENERATION.search(path.name)
        if m is not None and path.name == f"{segment.name}.spool.{m['n']}":
            found.append((int(m["n"]), path))
    return [p for _, p in sorted(found)]


def read_spool(segment: Path) -> Iterator[SpoolItem]:
    """Every complete record of ``segment``'s spool, in the order they were appended (a record
    cut short by the kill ends the generation)."""
    for path in spool_files(segment):
        data = path.read_bytes()
        pos = 0
        while pos + HEADER.size <= len(data):
            key_len, payload_len, log_ns, publish_ns, reply = HEADER.unpack_from(data, pos)
            start = pos + HEADER.size
            end = start + key_len + payload_len
            if end > len(data):
                break
            key = data[start : start + key_len].decode("utf-8", "replace")
            payload = data[start + key_len : end]
            yield key, payload, log_ns, (publish_ns if publish_ns >= 0 else None), bool(reply)
            pos = end


def durable_path(segment: Path) -> Path:
    """Where the receive time of the last message in a closed chunk is kept, with the newest
    tick of each per-tick stream there."""
    return segment.with_name(f"{segment.name}.spool.durable")


def read_durable(segment: Path) -> tuple[int, dict[str, int]]:
    """The receive time of the last message ``segment`` holds in a closed chunk (-1: none),
    and the newest tick of each per-tick stream in its closed chunks. A kill between a chunk's
    flush and this mark leaves it one chunk behind: the messages of that chunk are then
    recovered twice (never lost)."""
    try:
        data = durable_path(segment).read_bytes()
    except OSError:
        return -1, {}
    if len(data) < _MARK.size:
        return -1, {}
    durable_ns, size = _MARK.unpack_from(data)
    try:
        ticks = json.loads(data[_MARK.size : _MARK.size + size]) if size else {}
    except ValueError:
        ticks = {}
    return int(durable_ns), {str(k): int(v) for k, v in dict(ticks).items()}


def remove_spool(segment: Path) -> None:
    for path in spool_files(segment):
        path.unlink(missing_ok=True)
    durable_path(segment).unlink(missing_ok=True)


class Spool:
    """Appends records to ``<segment>.spool.<n>``; not thread-safe (the recorder holds its
    lock around :meth:`append` and :meth:`rotate`)."""

    def __init__(self, segment: Path) -> None:
        self._segment = segment
        remove_spool(segment)  # a spool of this segment's name is an older run's
        self._generation = 0
        self._fd = self._open(0)
        self._last_ns = -1  # receive time of the last record of the current generation
        self._closed: list[tuple[Path, int]] = []  # earlier generations and their last time
        self._durable_fd = os.open(durable_path(segment), os.O_WRONLY | os.O_CREAT, 0o644)
        self.bytes_written = 0

    def _path(self, n: int) -> Path:
        return self._segment.with_name(f"{self._segment.name}.spool.{n}")

    def _open(self, n: int) -> int:
        return os.open(self._path(n), os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_TRUNC, 0o644)

    def append(self, item: SpoolItem) -> None:
        key, payload, log_ns, publish_ns, reply = item
        raw_key = key.encode()
        header = HEADER.pack(
            len(raw_key), len(payload), log_ns, -1 if publish_ns is None else publish_ns, reply
        )
        self.bytes_written += os.writev(self._fd, (header, raw_key, payload))
        self._last_ns = log_ns

    def rotate(self, durable_ns: int, durable_ticks: dict[str, int]) -> None:
        """Every record received at or before ``durable_ns`` is in a closed chunk, and so is
        every tick up to ``durable_ticks[key]`` of each per-tick stream: mark it (one write), start
        a new generation and delete those whose records all are."""
        ticks = json.dumps(durable_ticks, separators=(",", ":")).encode()
        os.pwrite(self._durable_fd, _MARK.pack(durable_ns, len(ticks)) + ticks, 0)
        if self._last_ns >= 0:
            os.close(self._fd)
            self._closed.append((self._path(self._generation), self._last_ns))
            self._generation += 1
            self._fd = self._open(self._generation)
            self._last_ns = -1
        keep = []
        for path, last_ns in self._closed:
            if last_ns <= durable_ns:
                path.unlink(missing_ok=True)
            else:
                keep.append((path, last_ns))
        self._closed = keep

    def sync(self) -> None:
        """Force what was appended to the disk (``fsync``); raises ``OSError``."""
        os.fsync(self._fd)

    def abandon(self) -> None:
        """Close the files after a write error, keeping them: the next segment recovers what
        they hold that the abandoned segment does not."""
        for fd in (self._fd, self._durable_fd):
            with contextlib.suppress(OSError):
                os.close(fd)

    def close(self, remove: bool) -> None:
        os.close(self._fd)
        os.close(self._durable_fd)
        if remove:
            remove_spool(self._segment)
