"""Replay publishes a recording back with its order and timing (recorded again to compare)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import zenoh

from recorder.reader import Recording
from tests.support.procs import Network, NodeProcs, run_cli
from tests.support.recording import recorded_run, run_publisher, start_recorder
from tests.support.skewed_clock import faketime_library, skewed_clock_env

# Generous: two processes on a shared 2-core machine. Most messages must be within 50 ms of
# their recorded offset; a single scheduling stall may delay a burst further, not the stream.
TOLERANCE_S = 0.05
STALL_TOLERANCE_S = 0.25


def timeline(path: Path) -> list[tuple[str, bytes, float]]:
    """(key, stored data, seconds since the first) of vehicle messages, in file order.

    Times are publish times (the publishers' Zenoh timestamps): the original publisher's, then
    the replay's, so the comparison measures the replay's timing, not the recorder's wake-ups.
    """
    rows = [(m.topic, m.data, m.publish_time_ns) for m in Recording.open(path).messages()]
    rows = [r for r in rows if "/vehicle/" in r[0]]
    t0 = rows[0][2]
    return [(k, d, (t - t0) / 1e9) for k, d, t in rows]


@pytest.mark.parametrize("speed", [1.0, 2.0])
def test_replay_reproduces_order_and_timing(
    network: tuple[Network, zenoh.Session], tmp_path: Path, speed: float
) -> None:
    net, _ = network
    original = tmp_path / "original.mcap"
    again = tmp_path / "again.mcap"
    recorded_run(
        net,
        tmp_path,
        original,
        *("--steps", "40", "--rate-hz", "50", "--pause-at", "20", "--pause-s", "0.4"),
    )
    with NodeProcs(net, log_dir=tmp_path) as procs:
        procs.start("recorder", "--name", "recorder-b", "--set", f"out={again}", name="rec-b")
        result = run_cli(
            [
                "replay",
                str(original),
                *("--speed", str(speed), "--connect", net.endpoint),
                *("--recorded-by", "recorder-b"),
            ]
        )
        procs.stop_all()
    assert result.returncode == 0, result.stderr[-2000:]

    want = timeline(original)
    got = timeline(again)
    assert [(k, d) for k, d, _ in got] == [(k, d) for k, d, _ in want]
    errors = [abs(tg - tw / speed) for (_, _, tg), (_, _, tw) in zip(got, want, strict=True)]
    p95 = float(np.percentile(errors, 95))
    summary = f"timing error p95 {p95 * 1000:.0f} ms, worst {max(errors) * 1000:.0f} ms"
    assert p95 < TOLERANCE_S and max(errors) < STALL_TOLERANCE_S, summary
    assert want[-1][2] > 0.4 + 39 / 50 * 0.8  # the pause is in the original stream


@pytest.mark.skipif(faketime_library() is None, reason="libfaketime is not installed")
def test_replay_of_hosts_with_clocks_5_s_apart_is_paced_by_the_recorder_clock(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    """uav2's publisher, its clock 5 s behind, publishes first, then uav1's (on time): the
    replay sends uav1's messages when they came (the recorder's receive times), not 5 s late
    (docs/reliability.md, "Clocks of the hosts")."""
    net, _ = network
    original = tmp_path / "original.mcap"
    again = tmp_path / "again.mcap"
    with NodeProcs(net, log_dir=tmp_path) as procs:
        start_recorder(procs, original)
        steps = ("--steps", "20", "--rate-hz", "50")
        behind = skewed_clock_env(-5.0)
        run_publisher(net, tmp_path / "b.json", "--name", "pub-b", "--vehicles", "uav2", *steps,
                      env=behind)  # fmt: skip
        run_publisher(net, tmp_path / "a.json", "--name", "pub-a", "--vehicles", "uav1", *steps)
        procs.stop_all()
    recorded = [m for m in Recording.open(original).messages() if "/vehicle/" in m.topic]
    first = recorded[0]
    assert "uav2" in first.topic and first.log_time_ns - first.publish_time_ns > 4.5e9
    # when each came, in the recorder's clock, from the first
    want = [(m.topic, m.data, (m.log_time_ns - first.log_time_ns) / 1e9) for m in recorded]
    with NodeProcs(net, log_dir=tmp_path) as procs:
        procs.start("recorder", "--name", "recorder-b", "--set", f"out={again}", name="rec-b")
        result = run_cli(
            ["replay", str(original), "--connect", net.endpoint, "--recorded-by", "recorder-b"]
        )
        procs.stop_all()
    assert result.returncode == 0, result.stderr[-2000:]
    got = timeline(again)  # the replay's own clock: its publish times
    assert [(k, d) for k, d, _ in got] == [(k, d) for k, d, _ in want]
    on_time = [(tg, tw) for (k, _, tg), (_, _, tw) in zip(got, want, strict=True) if "uav1" in k]
    assert len(on_time) >= 20
    errors = [abs(tg - tw) for tg, tw in on_time]
    assert max(errors) < STALL_TOLERANCE_S, f"uav1's messages off by up to {max(errors):.2f} s"


@pytest.mark.parametrize(
    ("content", "message"),
    [(None, "no such file"), (b"hello", "not an MCAP file"), (b"", "not an MCAP file")],
)
def test_replay_bad_file_is_one_line(tmp_path: Path, content: bytes | None, message: str) -> None:
    path = tmp_path / "bad.mcap"
    if content is not None:
        path.write_bytes(content)
    result = run_cli(["replay", str(path), "--connect", "tcp/127.0.0.1:9"])
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.strip().splitlines()[-1] == f"plumeswarm: error: {path}: {message}"
