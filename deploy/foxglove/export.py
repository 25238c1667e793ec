"""``plumeswarm export foxglove IN OUT``: a recording with its Foxglove channels (re)made.

Every message of IN is copied as it is (channels, encodings, times); its bus messages are fed,
in file order, through the same conversion the recorder runs live
(:class:`~deploy.foxglove.scene.FoxgloveScene`), so a recording made without the Foxglove
channels (or by an older recorder) gets them, and one made with them gets them again, equal.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from deploy.foxglove.scene import FoxgloveScene
from deploy.recording import schema as sch
from deploy.recording.flight import scenario_of
from deploy.recording.reader import Recording, RecordingError
from deploy.recording.sink import McapSink

log = logging.getLogger(__name__)

Progress = Callable[[int], None]


class ExportError(RuntimeError):
    """The export could not be made: one line saying why."""


@dataclass(frozen=True)
class Exported:
    copied: int  # messages of IN
    foxglove: int  # Foxglove messages written
    truncated: bool  # IN was cut short (read to its last complete chunk)
    vehicle_ids: list[str]  # the vehicles seen, in order


def export_foxglove(src: str | Path, dst: Path, progress: Progress | None = None) -> Exported:
    """Write ``dst``: ``src`` (a recording, its first segment or its run directory) with the
    Foxglove channels. Raises :class:`ExportError` or :class:`RecordingError`."""
    recording = Recording.open(src)
    if dst.exists() and any(dst.resolve() == p.resolve() for p in recording.segments):
        raise ExportError(f"{dst}: is the recording being read; choose another output file")
    if dst.is_dir():
        raise ExportError(f"{dst}: is a directory")
    scenario = scenario_of(recording)
    metadata = recording.metadata.get("plumeswarm")
    try:
        sink = McapSink(dst, metadata=metadata)
    except OSError as exc:
        raise ExportError(f"cannot write {dst}: {exc.strerror or exc}") from None
    copied = foxglove = 0
    truncated = False
    vehicle_ids: dict[str, None] = {}
    summary: dict[str, str] | None = None
    try:
        # Each segment has its own scene, as the recorder that wrote it had.
        for path in recording.segments:
            segment = Recording(path, segments=[path])
            scene = FoxgloveScene(scenario)
            for rec in segment.messages():
                if rec.origin == sch.FOXGLOVE_ORIGIN:
                    continue  # made again below, from the bus messages
                message = sink.write_recorded(rec)
                copied += 1
                if message is not None:
                    for out in scene.feed(message, rec.log_time_ns):
                        sink.write_foxglove(out)
                        foxglove += 1
                sink.maybe_close_chunk()
                if progress is not None and copied % 10_000 == 0:
                    progress(copied)
            truncated |= segment.truncated
            if path == recording.segments[0]:  # its summary was read with its last record
                summary = segment.metadata.get("plumeswarm.summary")
            vehicle_ids.update(dict.fromkeys(scene.vehicle_ids))
        sink.close(summary)
    except (RecordingError, OSError) as exc:
        sink.close()
        os.unlink(dst)
        if isinstance(exc, RecordingError):
            raise
        raise ExportError(f"cannot write {dst}: {exc.strerror or exc}") from None
    return Exported(
        copied=copied,
        foxglove=foxglove,
        truncated=truncated,
        vehicle_ids=list(vehicle_ids),
    )
