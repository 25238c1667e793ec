"""Segments of one recording (a restarted recorder continues in ``<name>.1.mcap``): naming,
reading a cut segment's end, and reading every segment in order (no network)."""

from __future__ import annotations

from pathlib import Path

import pytest

from recorder import schema as sch
from recorder.reader import Recording, RecordingError, segment_end
from recorder.segments import next_segment, recording_files, segment_path
from recorder.sink import McapSink
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import SimTick
from tests.support.procs import run_cli

KEYS = Keys()


def write_ticks(path: Path, ticks: range, gap: sch.SegmentGap | None = None) -> None:
    sink = McapSink(path, chunk_interval_s=0.0, metadata={"world": "default"})
    if gap is not None:
        sink.write_gap(gap, 0)
    for k in ticks:
        tick = SimTick(tick=k, sim_time_s=k / 120, control_dt_s=1 / 120, states=[])
        sink.write_bus(KEYS.tick(), encode(tick), 1_000_000 * (k + 1))
        sink.maybe_close_chunk()
    sink.close()


def test_segment_names(tmp_path: Path) -> None:
    first = tmp_path / "recording.mcap"
    assert next_segment(first) == (None, first)
    first.write_bytes(b"")
    assert next_segment(first) == (first, tmp_path / "recording.1.mcap")
    segment_path(first, 1).write_bytes(b"")
    assert next_segment(first) == (segment_path(first, 1), tmp_path / "recording.2.mcap")
    assert recording_files(first) == [first, tmp_path / "recording.1.mcap"]
    assert recording_files(tmp_path) == [first, tmp_path / "recording.1.mcap"]
    assert recording_files(segment_path(first, 1)) == [segment_path(first, 1)]


def test_a_cut_segment_ends_at_its_last_complete_chunk(tmp_path: Path) -> None:
    path = tmp_path / "r.mcap"
    write_ticks(path, range(50))
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    end = segment_end(path)
    assert end.truncated
    assert end.last_tick is not None and 0 < end.last_tick < 49
    assert end.messages == end.last_tick + 1
    assert end.last_log_time_ns == 1_000_000 * (end.last_tick + 1)


def test_every_segment_is_read_in_order_with_its_gap(tmp_path: Path) -> None:
    first = tmp_path / "recording.mcap"
    write_ticks(first, range(10))
    gap = sch.SegmentGap(
        previous_segment=first.name, previous_truncated=False, previous_messages=10,
        previous_last_log_time_ns=10_000_000, previous_last_tick=9,
        previous_last_sim_time_s=9 / 120, first_log_time_ns=16_000_000, first_tick=15,
        first_sim_time_s=15 / 120, gap_s=0.006, ticks_missing=5,
    )  # fmt: skip
    write_ticks(segment_path(first, 1), range(15, 20), gap)
    for path in (first, tmp_path):
        recording = Recording.open(path)
        msgs = [m.message() for m in recording.messages() if m.topic == KEYS.tick()]
        ticks = [m.tick for m in msgs if isinstance(m, SimTick)]
        assert ticks == [*range(10), *range(15, 20)]
        assert recording.gaps() == [gap]
        assert recording.message_count == 10 + 6
        assert recording.metadata["plumeswarm"]["world"] == "default"


def test_unclear_directories_are_one_line_errors(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="without a recording"):
        Recording.open(tmp_path)
    write_ticks(tmp_path / "a.mcap", range(2))
    write_ticks(tmp_path / "b.mcap", range(2))
    with pytest.raises(RecordingError, match=r"several recordings \(a.mcap, b.mcap\)"):
        Recording.open(tmp_path)
    r = run_cli(["report", str(tmp_path), "--out", str(tmp_path / "rep")])
    assert r.returncode != 0 and "several recordings" in r.stderr
    assert "Traceback" not in r.stderr
