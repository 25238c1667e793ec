"""Names of a recording's segments: ``run.mcap``, then ``run.1.mcap``, ``run.2.mcap`` …

A recorder restarted after a crash never overwrites what its predecessor wrote: it continues in
the next free segment next to the first one (and records the gap there, see
:class:`recorder.schema.SegmentGap`). Readers take the first segment, or the directory
holding them, and read every segment in order.
"""

from __future__ import annotations

import re
from pathlib import Path

from swarmbus.errors import PlumeswarmError

SUFFIX = ".mcap"
_SEGMENT = re.compile(r"^(?P<stem>.+)\.(?P<n>[1-9][0-9]*)\.mcap$")


class SegmentError(PlumeswarmError, ValueError):
    """A path that does not name one recording."""


def segment_path(first: Path, n: int) -> Path:
    """Segment ``n`` of the recording whose first segment is ``first`` (0: ``first``)."""
    if n == 0:
        return first
    return first.with_name(f"{first.name.removesuffix(SUFFIX)}.{n}{SUFFIX}")


def segments_of(first: Path) -> list[Path]:
    """``first`` and its following segments that exist (consecutive numbers)."""
    out = [first]
    n = 1
    while (p := segment_path(first, n)).is_file():
        out.append(p)
        n += 1
    return out


def next_segment(first: Path) -> tuple[Path | None, Path]:
    """(the last existing segment or None, the path of the next one to write)."""
    n = 0
    while segment_path(first, n).exists():
        n += 1
    return (segment_path(first, n - 1) if n else None), segment_path(first, n)


def is_later_segment(path: Path) -> bool:
    return _SEGMENT.match(path.name) is not None


def recording_files(path: Path) -> list[Path]:
    """The segment files to read for ``path``: a first segment with its followers, a later
    segment alone, or the one recording in a directory."""
    if not path.is_dir():
        return [path] if is_later_segment(path) else segments_of(path)
    files = sorted(p for p in path.iterdir() if p.suffix == SUFFIX and p.is_file())
    firsts = [p for p in files if not is_later_segment(p)]
    if not files:
        raise SegmentError(f"{path}: is a directory without a recording (*{SUFFIX}) in it")
    if len(firsts) > 1:
        names = ", ".join(p.name for p in firsts)
        raise SegmentError(f"{path}: holds several recordings ({names}); name one of them")
    if not firsts:  # only later segments (the first was removed): read them in order
        return sorted(files, key=lambda p: int(_SEGMENT.match(p.name)["n"]))  # type: ignore[index]
    return segments_of(firsts[0])
