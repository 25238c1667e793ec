"""Where autopilot checkpoints are kept: the by-reference mission and fence lists in memory
(:class:`Blobs`, :data:`BLOBS`) and on disk (:class:`BlobLog`), and the two-slot checkpoint
files (:class:`CheckpointSlots`). :mod:`agents.checkpoint` makes and reads the checkpoints.
"""

from __future__ import annotations

import hashlib
import os
import struct
import zlib
from collections import OrderedDict
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec

from swarmbus.errors import PlumeswarmError


class CheckpointError(PlumeswarmError, ValueError):
    """A checkpoint that cannot be taken, read or restored; the message says which and why."""


class Blobs:
    """Encoded lists (missions, fence zones) by the digest of their encoding, in the order they
    were first seen. A list is replaced on upload, never changed in place, so it is encoded
    once while it is in use: a cache by the list's identity (holding the list keeps its id from
    being reused while it is cached) answers every later tick. Least recently used first out:
    the lists a process's vehicles fly are asked for every tick and stay; a replaced one is
    never asked for again and goes first. The encodings themselves stay (a checkpoint kept for a
    rewind may still refer to one); they grow with uploads only."""

    def __init__(self, cache_size: int = 1024) -> None:
        self.by_key: dict[str, msgspec.Raw] = {}
        self.order: list[str] = []  # keys in the order they were first seen
        self._cache: OrderedDict[int, tuple[list[Any], msgspec.Raw, str]] = OrderedDict()
        self._cache_size = cache_size

    def add(self, raw: msgspec.Raw | bytes) -> str:
        """The key of an encoding (kept if new)."""
        key = hashlib.blake2b(bytes(raw), digest_size=16).hexdigest()
        if key not in self.by_key:
            self.by_key[key] = msgspec.Raw(bytes(raw))
            self.order.append(key)
        return key

    def encoded(self, items: list[Any]) -> tuple[msgspec.Raw, str]:
        """``items`` encoded, and its key: once per list."""
        ident = id(items)
        hit = self._cache.get(ident)
        if hit is not None and hit[0] is items:
            self._cache.move_to_end(ident)
            return hit[1], hit[2]
        raw = msgspec.Raw(msgspec.msgpack.encode(items))
        key = self.add(raw)
        self._cache[ident] = (items, raw, key)
        self._cache.move_to_end(ident)
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return raw, key

    def get(self, key: str, what: str) -> msgspec.Raw:
        raw = self.by_key.get(key)
        if raw is None:
            raise CheckpointError(f"{what}: the saved list {key} is missing") from None
        return raw


#: Every encoded mission and fence list of this process (see :class:`Blobs`).
BLOBS = Blobs()

# ---------------------------------------------------------------------------- on disk
_HEAD = struct.Struct("<4sIIq")  # magic, CRC-32 of the payload, payload length, sequence
_MAGIC = b"APS1"


class CheckpointSlots:
    """The latest two records of one writer, in ``<path>.0`` and ``<path>.1`` in turn.

    A record is ``(sequence, payload)``; each write is one ``pwritev`` of a header (with a
    CRC-32 of the payload) and the payload at offset 0 of the older file. The file's pages
    survive a SIGKILL of the writer (they are the kernel's); a torn record fails its CRC and
    the other file still holds the previous one.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fds: list[int] = []
        self._seq = 0

    def paths(self) -> tuple[Path, Path]:
        return self.path.with_name(self.path.name + ".0"), self.path.with_name(
            self.path.name + ".1"
        )

    def open(self) -> None:
        """Open both files for writing (creating them); records already there stay readable
        until overwritten, and this writer's sequence continues after theirs."""
        try:
            self._fds = [os.open(p, os.O_RDWR | os.O_CREAT, 0o644) for p in self.paths()]
        except OSError as exc:
            raise CheckpointError(
                f"cannot write checkpoint {self.path}: {exc.strerror or exc}"
            ) from None
        self._seq = max((seq for seq, _ in self.read_all()), default=0)

    def write(self, payload: bytes) -> None:
        self._seq += 1
        head = _HEAD.pack(_MAGIC, zlib.crc32(payload), len(payload), self._seq)
        os.pwritev(self._fds[self._seq % 2], [head, payload], 0)  # one call, no joined copy

    def read_all(self) -> list[tuple[int, bytes]]:
        """The valid records, newest first."""
        return sorted(self._records(), reverse=True)

    def _records(self) -> Iterator[tuple[int, bytes]]:
        for p in self.paths():
            try:
                data = p.read_bytes()
            except OSError:
                continue
            if len(data) < _HEAD.size:
                continue
            magic, crc, length, seq = _HEAD.unpack_from(data)
            payload = data[_HEAD.size : _HEAD.size + length]
            if magic == _MAGIC and len(payload) == length and zlib.crc32(payload) == crc:
                yield seq, payload

    def close(self) -> None:
        for fd in self._fds:
            os.close(fd)
        self._fds = []

    def remove(self) -> None:
        for p in self.paths():
            p.unlink(missing_ok=True)


_BLOB_HEAD = struct.Struct("<4sI16s")  # magic, payload length, blake2b-128 of the payload
_BLOB_MAGIC = b"APB1"


class BlobLog:
    """The encoded lists of :data:`BLOBS` (missions, fence zones) on disk: each appended once,
    in one write, before a checkpoint that refers to it is written (:meth:`flush`). A record
    whose digest does not match (a write cut short by a kill) ends the log: it is cut off
    there when the log is opened again."""

    def __init__(self, path: Path, blobs: Blobs = BLOBS) -> None:
        self.path = path
        self.blobs = blobs
        self._fd = -1
        self._written: set[str] = set()
        self._next = 0  # blobs.order[:_next] are written (or were already on disk)

    def open(self) -> None:
        """Give the lists already in the log to :data:`BLOBS`, then append after them."""
        end = 0
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            data = b""
        except OSError as exc:
            raise CheckpointError(f"cannot read {self.path}: {exc.strerror or exc}") from None
        for key, payload, after in _blob_records(data):
            self.blobs.add(payload)
            self._written.add(key)
            end = after
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            os.ftruncate(self._fd, end)  # a torn last record
            os.lseek(self._fd, end, os.SEEK_SET)
        except OSError as exc:
            raise CheckpointError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._next = 0

    def flush(self) -> None:
        """Append the lists first seen since the last call (nothing, almost every tick)."""
        order = self.blobs.order
        if self._next == len(order) or self._fd < 0:
            return
        for key in order[self._next :]:
            if key in self._written:
                continue
            payload = bytes(self.blobs.by_key[key])
            head = _BLOB_HEAD.pack(_BLOB_MAGIC, len(payload), bytes.fromhex(key))
            os.writev(self._fd, [head, payload])
            self._written.add(key)
        self._next = len(order)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = -1


def _blob_records(data: bytes) -> Iterator[tuple[str, bytes, int]]:
    """(key, payload, offset after it) of the valid records at the start of ``data``."""
    at = 0
    while at + _BLOB_HEAD.size <= len(data):
        magic, length, digest = _BLOB_HEAD.unpack_from(data, at)
        start = at + _BLOB_HEAD.size
        payload = data[start : start + length]
        if magic != _BLOB_MAGIC or len(payload) != length:
            return
        if hashlib.blake2b(payload, digest_size=16).digest() != digest:
            return
        at = start + length
        yield digest.hex(), payload, at
