"""Where an autopilot process keeps its checkpoints (``--set checkpoint=PATH``) and which one a tick
resumes from (:class:`StateKeeper`). See docs/agents.md ("Restarts: the autopilot resumes where
it was").
"""

from __future__ import annotations

import logging
from pathlib import Path

from agents.checkpoint import ProcessCheckpoint, decode_process, missing_lists
from agents.checkpoint_store import BlobLog, CheckpointError, CheckpointSlots

log = logging.getLogger(__name__)


def checkpoint_paths(path: Path) -> list[Path]:
    """Every file a keeper at ``path`` writes (the launcher removes them for a fresh run)."""
    return [*CheckpointSlots(path).paths(), *CheckpointSlots(_ckpt(path)).paths(), _blobs(path)]


def _ckpt(path: Path) -> Path:
    return path.with_name(path.name + ".ckpt")


def _blobs(path: Path) -> Path:
    return path.with_name(path.name + ".blobs")


class StateKeeper:
    """The checkpoints of one autopilot process (see the module doc)."""

    def __init__(self, path: Path, period_ticks: int) -> None:
        self.path = path
        self.period_ticks = period_ticks
        self._slots = CheckpointSlots(path)
        self._ckpt = CheckpointSlots(_ckpt(path))
        self._blobs = BlobLog(_blobs(path))
        self._found: list[ProcessCheckpoint] = []  # what a killed predecessor left
        self._last = b""  # the latest checkpoint (not necessarily written yet)
        self._at_checkpoint: dict[int, bytes] = {}  # tick → checkpoint, the latest two

    def open(self, initial: bytes) -> None:
        """Read what a predecessor left, then open the files; ``initial`` is the fresh
        process's own checkpoint (tick -1: the state before tick 0)."""
        self._blobs.open()  # the lists the checkpoints found refer to
        for slots in (self._slots, self._ckpt):
            for _, payload in slots.read_all():
                try:
                    self._found.append(decode_process(payload))
                except CheckpointError as exc:
                    log.warning("ignoring %s: %s", slots.path, exc)
            slots.open()
        self._last = initial
        if self._found:
            ticks = sorted({s.tick for s in self._found})
            log.info("checkpoints of ticks %s found in %s*", ticks, self.path)

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

    def oldest_kept(self) -> int | None:
        """The oldest checkpoint tick whose state before it is kept (a rewind's furthest)."""
        return min(self._at_checkpoint, default=None)

    def latest_found(self) -> ProcessCheckpoint | None:
        """The predecessor's last checkpoint (the most commands of its last tick)."""
        return max(self._found, key=lambda s: (s.tick, len(s.handled)), default=None)

    def for_restart(self, tick: int) -> ProcessCheckpoint | None:
        """A restarted process's first tick: the predecessor's checkpoint of ``tick - 1`` (or of
        ``tick``, already answered), or None."""
        found = self._found
        for want in (tick - 1, tick):
            match = next((s for s in found if s.tick == want), None)
            if match is not None:
                return _complete(match)
        if found:
            log.warning(
                "no checkpoint for tick %d (found ticks %s): not restored",
                tick,
                sorted({s.tick for s in found}),
            )
        return None

    def for_rewind(self, tick: int) -> ProcessCheckpoint | None:
        """The tick went back to ``tick`` (a physics checkpoint): the state before it."""
        payload = self._at_checkpoint.get(tick)
        if payload is not None:
            return _complete(decode_process(payload))
        match = next((s for s in self._found if s.tick == tick - 1), None)
        return None if match is None else _complete(match)


def _complete(snap: ProcessCheckpoint) -> ProcessCheckpoint | None:
    """``snap``, or None when a list it refers to is missing (it cannot be restored)."""
    missing = missing_lists(snap)
    if missing:
        log.warning(
            "checkpoint of tick %d refers to %d missing mission/fence lists (%s): not restored",
            snap.tick,
            len(missing),
            missing[0],
        )
        return None
    return snap
