"""The recorder's queue is bounded in bytes as well as in messages: what arrives beyond
``max_backlog_bytes`` of queued payloads is dropped, counted per key, logged as an error and
recorded (a ``dropped`` event, the summary). A real recorder (real session, MCAP sink and
spool) fed by Zenoh while its writer has not started yet, so the queue only fills."""

from __future__ import annotations

import json
import logging
import threading
from pathlib import Path

import pytest
import zenoh

from recorder.node import Recorder, RecorderOptions
from recorder.reader import Recording
from recorder.sink import McapSink
from recorder.spool import Spool
from swarmbus.session import open_session
from tests.support.procs import Network, keys_for, wait_until

KEYS = keys_for()
MIB = 2**20


def test_a_queue_over_its_byte_bound_drops_counts_logs_and_records(
    network: tuple[Network, zenoh.Session], tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    net, _ = network
    opts = RecorderOptions(
        out=str(tmp_path / "bounded.mcap"),
        max_backlog_bytes=MIB,
        query_plume_info=False,
        foxglove=False,
    )
    out = Path(opts.out)
    size = 300_000  # 3 fit in 1 MiB (900 000 bytes), a fourth does not (1 200 000 > 1 048 576)
    sent = 10
    key = KEYS.vehicle_status("uav1")
    healths: list[str] = []
    with open_session(net.client) as session, caplog.at_level(logging.ERROR, "recorder.node"):
        recorder = Recorder(
            session,
            KEYS,
            "recorder",
            McapSink(out),
            opts,
            lambda detail, _state: healths.append(detail),
            spool=Spool(out),
        )
        seen = threading.Semaphore(0)

        def feed(sample: zenoh.Sample) -> None:  # what the recorder's own subscriber does
            recorder._on_sample(sample)
            seen.release()

        sub = session.declare_subscriber(key, feed)
        pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: bool(_matching(pub)), 10.0, "the feed subscribed")
        for k in range(sent):
            pub.put(bytes([k]) * size)
        for _ in range(sent):
            assert seen.acquire(timeout=30.0)
        sub.undeclare()
        pub.undeclare()
        assert recorder.backlog == 3
        assert recorder.dropped == {key: sent - 3}
        recorder.start()  # the writer drains the queue and reports the drops
        wait_until(lambda: recorder.backlog == 0, 30.0, "the queue written")
        recorder.stop()
    errors = [r.getMessage() for r in caplog.records if r.levelno >= logging.ERROR]
    assert any(
        "RECORDER DROPPED MESSAGES: 7 messages dropped (queue full: at most 2000000 messages, "
        "1048576 bytes)" in line
        for line in errors
    ), errors
    assert any(h.endswith("dropped 7") for h in healths), healths
    recording = Recording.open(out)
    kept = [m.data for m in recording.messages() if m.topic == key]
    assert kept == [bytes([k]) * size for k in range(3)]
    drops = [
        e for m in recording.messages() if (e := m.event()) is not None and e.kind == "dropped"
    ]
    assert [e.dropped for e in drops] == [7]
    summary = recording.metadata["plumeswarm.summary"]
    assert json.loads(summary["dropped"]) == {key: 7}


def _matching(pub: zenoh.Publisher) -> bool:
    status: object = pub.matching_status  # a MatchingStatus (the stub says bool)
    return bool(getattr(status, "matching", False))
