"""A recorder killed just after its writer closed a chunk, when its spool holds nothing the
file does not: the physics re-sends its recent ticks to the restarted recorder, which records
only those the killed segment's file does not hold, so no tick is recorded twice and the gap
record counts none missing. A real MCAP sink and spool make the killed segment; a real
recorder (real session) restarts after it and real puts on ``sim/backfill`` reach it."""

from __future__ import annotations

import time
from pathlib import Path

import zenoh

from recorder.node import Recorder, RecorderOptions
from recorder.reader import Recording
from recorder.sink import McapSink
from recorder.spool import Spool, read_durable, spool_files
from swarmbus.codec import encode
from swarmbus.messages import SimTick
from swarmbus.session import open_session
from tests.support.procs import Network, keys_for, wait_until

KEYS = keys_for()
WRITTEN, RESENT = 10, 12  # ticks in the killed segment's file; the last ticks re-sent


def _tick(k: int) -> bytes:
    return encode(SimTick(tick=k, sim_time_s=k / 120, control_dt_s=1 / 120, states=[]))


def _killed_segment(path: Path) -> None:
    """Ticks 1..WRITTEN in a closed chunk, the spool marked and rotated: then the kill."""
    sink, spool = McapSink(path), Spool(path)
    t0_ns = time.time_ns() - 1_000_000_000
    for k in range(1, WRITTEN + 1):
        item = (KEYS.tick(), _tick(k), t0_ns + k, None, False)
        spool.append(item)
        sink.write_bus(*item[:3])
    assert sink.maybe_close_chunk(now_monotonic=float("inf"))
    spool.rotate(t0_ns + WRITTEN, {KEYS.tick(): WRITTEN})
    sink.abandon()  # what the kill leaves: the descriptors closed
    spool.abandon()


def test_ticks_resent_after_a_kill_are_recorded_once(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    killed = tmp_path / "run.mcap"
    _killed_segment(killed)
    assert [p.name for p in spool_files(killed)] == ["run.mcap.spool.1"]  # empty: all is durable
    assert read_durable(killed)[1] == {KEYS.tick(): WRITTEN}

    new = tmp_path / "run.1.mcap"
    opts = RecorderOptions(out=str(new), query_plume_info=False, foxglove=False)
    resent = range(WRITTEN + 1 - RESENT // 2, WRITTEN + 1 + RESENT // 2)  # 5..16
    with open_session(net.client) as session:
        recorder = Recorder(
            session,
            KEYS,
            "recorder",
            McapSink(new),
            opts,
            lambda _detail, _state: None,
            previous_segment=killed,
            spool=Spool(new),
        )
        recorder.start()
        assert recorder.recovered == 0
        for k in resent:  # what the physics does for a restarted recorder
            session.put(KEYS.backfill_of(KEYS.tick()), _tick(k))
        session.put(KEYS.tick(), _tick(resent[-1] + 1))  # then the clock goes on
        taken = resent[-1] - WRITTEN + 1  # the ticks the file lacks
        wait_until(lambda: recorder.received[KEYS.tick()] >= taken, 30.0, "the ticks taken")
        wait_until(lambda: recorder.backlog == 0, 30.0, "the queue written")
        assert recorder.stop()

    recording = Recording(new, segments=[new])
    ticks = [m.message() for m in recording.messages() if m.topic == KEYS.tick()]
    recorded = [t.tick for t in ticks if isinstance(t, SimTick)]
    assert recorded == list(range(WRITTEN + 1, resent[-1] + 2))
    assert recorder.backfilled == resent[-1] - WRITTEN
    (gap,) = recording.gaps()
    assert (gap.previous_last_tick, gap.first_tick, gap.ticks_missing) == (WRITTEN, WRITTEN + 1, 0)
