"""The recorder on a real Zenoh network: what is published is what is recorded, in order."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import zenoh

from recorder.reader import Recording
from swarmbus.codec import encode
from tests.support.procs import REPO, Network, NodeProcs, keys_for, run_cli, wait_until
from tests.support.recording import (
    finish_publisher,
    published_messages,
    recorded_run,
    run_publisher,
    start_publisher,
    start_recorder,
)

KEYS = keys_for()


def vehicle_messages(recording: Recording) -> list[tuple[str, bytes]]:
    """(key, bus payload) of every vehicle-plane message, in file order."""
    out = []
    for rec in recording.messages():
        if "/vehicle/" not in rec.topic:
            continue
        msg = rec.message()
        out.append((rec.topic, encode(msg) if msg is not None else rec.data))
    return out


def test_round_trip_same_messages_in_order(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    out = tmp_path / "round_trip.mcap"
    published = recorded_run(
        net, tmp_path, out, "--vehicles", "uav1,uav2", "--steps", "60", "--garbage"
    )
    recording = Recording.open(out)
    assert not recording.truncated
    assert vehicle_messages(recording) == published_messages(published)
    # publish_time is the publisher's own clock: between its readings after the previous put and
    # after this one (the scripted publisher notes time.time_ns() after each put).
    times = [r.publish_time_ns for r in recording.messages() if "/vehicle/" in r.topic]
    after_put = [t for _, _, t in published["published"]]
    for i, (t, after) in enumerate(zip(times, after_put, strict=True)):
        assert (after_put[i - 1] if i else 0) <= t <= after, f"message {i}: publish time {t}"
    assert recording.metadata["plumeswarm"]["world"] == "default"
    summary = recording.metadata["plumeswarm.summary"]
    assert json.loads(summary["dropped_total"]) == 0
    assert json.loads(summary["undecodable"]) == {KEYS.vehicle_status("uav1"): 1}


def test_sigkill_leaves_completed_chunks_readable(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    out = tmp_path / "killed.mcap"
    with NodeProcs(net, log_dir=tmp_path) as procs:
        rec = start_recorder(procs, out, "--set", "chunk_interval_s=0.2")
        published = run_publisher(
            net, tmp_path / "pub.json", "--vehicles", "uav1", "--steps", "100", "--rate-hz", "100"
        )
        # Everything was acknowledged; a chunk closes at most 0.2 s after its first message.
        size = wait_until(
            lambda: _complete_chunks_cover(out, len(published["published"])),
            20.0,
            "the recorder to close the chunk holding the last message",
        )
        procs.kill(rec)
    assert size
    recording = Recording.open(out)
    got = vehicle_messages(recording)
    assert recording.truncated
    assert got == published_messages(published)


def _complete_chunks_cover(path: Path, n_vehicle_messages: int) -> bool:
    if not path.exists():
        return False
    return len(vehicle_messages(Recording.open(path))) >= n_vehicle_messages


def test_record_command_closes_cleanly_on_sigint(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    out = tmp_path / "cli.mcap"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    cmd = [
        sys.executable,
        "-m",
        "plumeswarm",
        "record",
        "--connect",
        net.endpoint,
        "--out",
        str(out),
    ]
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stderr=subprocess.PIPE, start_new_session=True)
    try:
        published = run_publisher(net, tmp_path / "pub.json", "--steps", "20")
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    assert proc.returncode == 0, err.decode()[-2000:]
    recording = Recording.open(out)
    assert not recording.truncated
    assert recording.message_count is not None  # the summary (index) is there
    assert len(vehicle_messages(recording)) == len(published["published"])


def test_record_command_unwritable_output_is_one_line(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = run_cli(["record", "--out", str(blocker / "x.mcap"), "--connect", "tcp/127.0.0.1:9"])
    assert result.returncode != 0
    assert "Traceback" not in result.stderr
    assert "error" in result.stderr.splitlines()[-1]


def test_eight_vehicles_every_published_message_is_recorded(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    out = tmp_path / "eight.mcap"
    groups = {"pub-a": "uav1,uav2,uav3,uav4", "pub-b": "uav5,uav6,uav7,uav8"}
    with NodeProcs(net, log_dir=tmp_path) as procs:
        rec = start_recorder(procs, out)
        pubs = {
            name: start_publisher(
                net,
                tmp_path / f"{name}.json",
                *("--name", name, "--vehicles", vehicles, "--steps", "240", "--rate-hz", "120"),
            )
            for name, vehicles in groups.items()
        }
        results = {name: finish_publisher(p, tmp_path / f"{name}.json") for name, p in pubs.items()}
        procs.stop_all()
    assert rec.returncode == 0

    published: dict[str, int] = {}
    for result in results.values():
        published.update(result["counts"])
    assert len(published) == 8 * 3
    recorded: dict[str, int] = {}
    for m in Recording.open(out).messages():
        if m.topic in published:
            recorded[m.topic] = recorded.get(m.topic, 0) + 1
    assert recorded == published


def test_ticks_missing_from_a_state_stream_are_counted_and_recorded(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    out = tmp_path / "gaps.mcap"
    recorded_run(net, tmp_path, out, *("--steps", "30", "--skip-at", "10", "--skip-n", "5"))
    recording = Recording.open(out)
    gaps = [e for m in recording.messages() if (e := m.event()) is not None and e.kind == "gap"]
    assert [e.lost_upstream for e in gaps] == [5]
    summary = recording.metadata["plumeswarm.summary"]
    assert json.loads(summary["tick_gaps"]) == {KEYS.vehicle_state("uav1"): 5}
