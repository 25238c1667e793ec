"""When the physics saves its world, and resuming from the last save at start.

See docs/physics.md, "Checkpoints and restart".
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import msgspec

from sim_world import checkpoint
from sim_world.checkpoint import CheckpointWriter, ProgressMarker, WorldCheckpoint
from swarmbus.messages import PlumeSample

if TYPE_CHECKING:
    from sim_world.world import World

log = logging.getLogger(__name__)


class Checkpointer:
    """Saves the world every ``period_s`` of sim time (on ticks that are multiples of the
    period, and at the first tick) to ``path``; notes every published tick in the progress
    marker. The loop's per-tick cost is one comparison with :attr:`next_tick`."""

    def __init__(
        self,
        path: Path | None,
        period_s: float,
        control_hz: int,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.path = path
        self._control_hz = control_hz
        self._clock = clock
        self._period_ticks = 0  # 0: never
        if path is not None and period_s > 0.0:
            self._period_ticks = max(1, round(period_s * control_hz))
        self.next_tick = sys.maxsize  # call save() at this tick (a save due, or one on disk)
        self._due = sys.maxsize
        self._writer: CheckpointWriter | None = None
        self._marker: ProgressMarker | None = None
        self.capture_s = 0.0
        self.note = ""  # what was resumed, for the log and the health detail
        self._last_run_wall: float | None = None  # the last run's last tick's wall time

    def resume(self, world: World) -> WorldCheckpoint | None:
        """Restore ``world`` from the checkpoint file if there is one; returns it."""
        if self.path is None:
            return None
        last = ProgressMarker.read(checkpoint.marker_path(self.path))
        if not self.path.exists():
            return None
        cp = checkpoint.load(self.path)
        world.restore(cp)
        self.note = f"resumed from checkpoint at tick {cp.tick} (sim t={cp.sim_time_s:.3f} s)"
        if last is not None and last[0] >= cp.tick:
            replayed_s = (last[0] - cp.tick) / self._control_hz
            self.note += f", replayed {replayed_s:.3f} s (ticks {cp.tick}..{last[0]})"
        log.warning("%s", self.note)
        self._last_run_wall = last[1] if last is not None else None
        return cp

    def start(self, world: World, tick: int, carried: PlumeSample | None) -> None:
        """Open the file and the marker; save ``tick`` unless it was just resumed (so a kill
        before the first period resumes from the spawn)."""
        if not self._period_ticks:
            return
        assert self.path is not None
        self._marker = ProgressMarker(checkpoint.marker_path(self.path))
        self._writer = CheckpointWriter(self.path)
        self._due = tick + (self._period_ticks if self.note else 0)
        self.save(world, tick, carried)

    def started(self) -> None:
        """The first tick was answered: say how long ticks stopped between the runs."""
        if self._last_run_wall is not None and self.note:
            self.note += f", ticks stopped for {self._clock() - self._last_run_wall:.2f} s wall"
            log.warning("%s", self.note)

    def save(self, world: World, tick: int, carried: PlumeSample | None) -> None:
        """Capture the world of a due tick (carrying ``carried``) before it is published; the
        writer saves it while the tick's round trip runs, and the next tick waits until it is
        on disk, so the file is never more than one period behind a published tick (the most
        a restart replays)."""
        writer = self._writer
        assert writer is not None
        writer.wait()
        if tick >= self._due:
            t0 = self._clock()
            cp = world.checkpoint(tick)
            if carried is not None:  # the values this tick carries
                cp = msgspec.structs.replace(cp, plume_sample=carried)
            writer.submit(cp)
            self.capture_s += self._clock() - t0
            self._due = tick + self._period_ticks
        self.next_tick = tick + 1 if writer.pending else self._due

    def mark(self, tick: int) -> None:
        """``tick`` was published (noted in the progress marker)."""
        if self._marker is not None:
            self._marker.mark(tick)

    def finish(self) -> None:
        """The last save on disk; its figures logged."""
        w = self._writer
        if w is None:
            return
        w.wait()
        log.info(
            "%d checkpoints: capture %.2f ms, write %.2f ms (longest %.2f ms) on average; "
            "the loop waited %.1f ms for writes in all",
            w.written,
            1e3 * self.capture_s / max(1, w.written),
            1e3 * w.write_s / max(1, w.written),
            1e3 * w.longest_write_s,
            1e3 * w.waited_s,
        )

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
        if self._marker is not None:
            self._marker.close()
