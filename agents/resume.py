"""Where an autopilot process keeps its snapshots (``--set checkpoint=PATH``) and which one a tick
resumes from (:class:`StateKeeper`). See docs/agents.md ("Restarts: the autopilot resumes where
it was").
"""

from __future__ import annotations

import logging
from pathlib import Path

from agents.snapshot import ProcessSnapshot, decode_process, missing_lists
from agents.snapshot_store import BlobLog, SnapshotError, SnapshotSlots

log = logging.getLogger(__name__)


def snapshot_paths(path: Path) -> list[Path]:
    """Every file a keeper at ``path`` writes (the launcher removes them for a fresh run)."""
    return [*SnapshotSlots(path).paths(), *SnapshotSlots(_ckpt(path)).paths(), _blobs(path)]


def _ckpt(path: Path) -> Path:
    return path.with_name(path.name + ".ckpt")


def _blobs(path: Path) -> Path:
    return path.with_name(path.name + ".blobs")


class StateKeeper:
    """The snapshots of one autopilot process (see the module doc)."""

    def __init__(self, path: Path, period_ticks: int) -> None:
        self.path = path
        self.period_ticks = period_ticks
        self._slots = SnapshotSlots(path)
        self._ckpt = SnapshotSlots(_ckpt(path))
        self._blobs = BlobLog(_blobs(path))
        self._found: list[ProcessSnapshot] = []  # what a killed predecessor left
        self._last = b""  # the latest snapshot (not necessarily written yet)
        self._at_checkpoint: dict[int, bytes] = {}  # tick → snapshot, the latest two

    def open(self, initial: bytes) -> None:
        """Read what a predecessor left, then open the files; ``initial`` is the fresh
        process's own snapshot (tick -1: the state before tick 0)."""
        self._blobs.open()  # the lists the snapshots found refer to
        for slots in (self._slots, self._ckpt):
            for _, payload in slots.read_all():
                try:
                    self._found.append(decode_process(payload))
                except SnapshotError as exc:
                    log.warning("ignoring %s: %s", slots.path, exc)
            slots.open()
        self._last = initial
        if self._found:
            ticks = sorted({s.tick for s in self._found})
            log.info("snapshots of ticks %s found in %s*", ticks, self.path)

    def close(self) -> None:
        self._slots.close()
        self._ckpt.close()
        self._blobs.close()

    def save(self, payload: bytes) -> None:
        """The process's state now (after a tick's answer was computed, or a command)."""
        self._last = payload
        self._blobs.flush()  # the lists it refers to, before it
        self._slots.write(payload)

    def before_tick(self, tick: int) -> None:
        """Tick ``tick`` is about to be handled: on a checkpoint tick keep the state before it."""
        if self.period_ticks and tick % self.period_ticks == 0 and self._last:
            self._blobs.flush()
            self._ckpt.write(self._last)
            self._at_checkpoint[tick] = self._last
            for old in sorted(self._at_checkpoint)[:-2]:
                del self._at_checkpoint[old]

    def for_restart(self, tick: int) -> ProcessSnapshot | None:
        """A restarted process's first tick: the predecessor's snapshot of ``tick - 1`` (or of
        ``tick``, already answered), or None."""
        found = self._found
        for want in (tick - 1, tick):
            match = next((s for s in found if s.tick == want), None)
            if match is not None:
                return _complete(match)
        if found:
            log.warning(
                "no snapshot for tick %d (found ticks %s): not restored",
                tick,
                sorted({s.tick for s in found}),
            )
        return None

    def for_rewind(self, tick: int) -> ProcessSnapshot | None:
        """The tick went back to ``tick`` (a physics checkpoint): the state before it."""
        payload = self._at_checkpoint.get(tick)
        if payload is not None:
            return _complete(decode_process(payload))
        match = next((s for s in self._found if s.tick == tick - 1), None)
        return None if match is None else _complete(match)


def _complete(snap: ProcessSnapshot) -> ProcessSnapshot | None:
    """``snap``, or None when a list it refers to is missing (it cannot be restored)."""
    missing = missing_lists(snap)
    if missing:
        log.warning(
            "snapshot of tick %d refers to %d missing mission/fence lists (%s): not restored",
            snap.tick,
            len(missing),
            missing[0],
        )
        return None
    return snap
