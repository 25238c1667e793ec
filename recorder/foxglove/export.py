"""``plumeswarm export foxglove IN OUT``: a recording with its Foxglove channels (re)made.

Every message of IN is copied as it is (channels, encodings, times); its bus messages are fed,
in file order, through the same conversion the recorder runs live
(:class:`~recorder.foxglove.scene.FoxgloveScene`), so a recording made without the Foxglove
channels (or by an older recorder) gets them, and one made with them gets them again, equal.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from recorder import schema as sch
from recorder.flight_log import scenario_of
from recorder.foxglove.scene import (
    FoxgloveScene,
)
from recorder.reader import ExportError, Recording, RecordingError
from recorder.sink import McapSink

log = logging.getLogger(__name__)

Progress = Callable[[int], None]


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
    sink = _open_sink(recording, dst)
    scenario = scenario_of(recording)
    tally = _Tally()
    summary: dict[str, str] | None = None
    try:
        # Each segment has its own scene, as the recorder that wrote it had.
        for path in recording.segments:
            segment = Recording(path, segments=[path])
            _export_segment(segment, FoxgloveScene(scenario), sink, tally, progress)
            if path == recording.segments[0]:  # its summary was read with its last record
                summary = segment.metadata.get("plumeswarm.summary")
        sink.close(summary)
    except (RecordingError, OSError) as exc:
        sink.close()
        os.unlink(dst)
        if isinstance(exc, RecordingError):
            raise
        raise ExportError(f"cannot write {dst}: {exc.strerror or exc}") from None
    return Exported(
        copied=tally.copied,
        foxglove=tally.foxglove,
        truncated=tally.truncated,
        vehicle_ids=list(tally.vehicle_ids),
    )


@dataclass
class _Tally:
    copied: int = 0
    foxglove: int = 0
    truncated: bool = False
    vehicle_ids: dict[str, None] = field(default_factory=dict)  # in order of appearance


def _open_sink(recording: Recording, dst: Path) -> McapSink:
    if dst.exists() and any(dst.resolve() == p.resolve() for p in recording.segments):
        raise ExportError(f"{dst}: is the recording being read; choose another output file")
    if dst.is_dir():
        raise ExportError(f"{dst}: is a directory")
    try:
        return McapSink(dst, metadata=recording.metadata.get("plumeswarm"))
    except OSError as exc:
        raise ExportError(f"cannot write {dst}: {exc.strerror or exc}") from None


def _export_segment(
    segment: Recording,
    scene: FoxgloveScene,
    sink: McapSink,
    tally: _Tally,
    progress: Progress | None,
) -> None:
    """Copy one segment's messages and write its Foxglove messages made anew from them."""
    for rec in segment.messages():
        if rec.origin == sch.FOXGLOVE_ORIGIN:
            continue  # made again below, from the bus messages
        message = sink.write_recorded(rec)
        tally.copied += 1
        if message is not None:
            for out in scene.feed(message, rec.log_time_ns):
                sink.write_foxglove(out)
                tally.foxglove += 1
        sink.maybe_close_chunk()
        if progress is not None and tally.copied % 10_000 == 0:
            progress(tally.copied)
    tally.truncated |= segment.truncated
    tally.vehicle_ids.update(dict.fromkeys(scene.vehicle_ids))
