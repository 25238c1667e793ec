"""The recorder on a full disk (lockstep): ``plumeswarm up --record`` with the recording on a
2 MiB tmpfs of its own. The disk is filled while the run records: the recorder's health turns
to ``error`` with the reason (the bus, ``plumeswarm status --json``, the launcher's log), the
clock holds, no process stops; space freed, recording goes on in the next segment with the gap
recorded there, and the clock goes on. Needs root (to mount the tmpfs)."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy.launcher import Launcher
from deploy.supervisor import ProcState
from recorder.reader import Recording, segment_end
from swarmbus.codec import decode
from swarmbus.messages import NodeState, SimTick
from swarmbus.scenario import load_scenario
from swarmbus.session import free_tcp_port
from tests.support.mavclient import write_scenario
from tests.support.procs import keys_for, run_cli, wait_until
from tests.support.recording import ticks_not_recorded
from tests.support.upstack import recording_launch


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    """A 2 MiB tmpfs, unmounted afterwards."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    mnt = tmp_path / "disk"
    mnt.mkdir()
    mounted = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True
    )
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {mounted.stderr.decode().strip()}")
    try:
        yield mnt
    finally:
        if subprocess.run(["umount", str(mnt)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mnt)], capture_output=True)


def fill(path: Path) -> None:
    """Write zeros to ``path`` until the file system says it is full."""
    block = bytes(1 << 16)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        while True:
            os.write(fd, block)
    except OSError as exc:
        assert exc.errno == errno.ENOSPC, exc
        try:  # the last partial block
            while os.write(fd, b"\0"):
                pass
        except OSError:
            pass
    finally:
        os.close(fd)


@pytest.mark.parametrize("spool", [True, False], ids=["spool", "mcap-writer"])
def test_full_disk_is_reported_held_and_recovered(
    tmp_path: Path, small_disk: Path, caplog: pytest.LogCaptureFixture, spool: bool
) -> None:
    """With the spool, its write fails first; without, the MCAP writer's chunk flush."""
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 2)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    out = small_disk / "recording.mcap"
    opts = recording_launch(
        path,
        tmp_path / "run",
        endpoint,
        node_options={
            "recorder": (
                f"out={out}",
                "resume_free_bytes=262144",
                "foxglove=false",
                f"spool={str(spool).lower()}",
            )
        },
    )
    caplog.set_level("WARNING", logger="deploy.launcher")
    keys = keys_for()
    launcher = Launcher(load_scenario(path), opts)
    lock = threading.Lock()
    ticks: list[int] = []

    def on_bus(session: zenoh.Session) -> None:
        def on_tick(sample: zenoh.Sample) -> None:
            with lock:
                ticks.append(decode(sample.payload.to_bytes(), SimTick).tick)

        subs.append(session.declare_subscriber(keys.tick(), on_tick))

    def last_tick() -> int:
        launcher.supervise_once()
        with lock:
            return ticks[-1] if ticks else -1

    def recorder_state() -> NodeState | None:
        launcher.supervise_once()
        assert launcher.view is not None
        h = launcher.view.snapshot().health.get("recorder")
        return h.state if h is not None else None

    subs: list[zenoh.Subscriber[None]] = []
    try:
        launcher.start(on_bus)
        wait_until(
            lambda: last_tick() >= 200 and segment_end(out).last_tick is not None,
            120.0,
            "ticks in a closed chunk",
        )
        pids = launcher.supervisor.pids()
        fill(small_disk / "fill")
        filled_at = last_tick()
        wait_until(lambda: recorder_state() is NodeState.ERROR, 5.0, "the recorder's error")
        status = run_cli(
            ["status", "--scenario", str(path), "--json", "--connect", endpoint, "--timeout", "3"]
        )
        assert status.returncode == 0, status.stderr
        node = {n["name"]: n for n in json.loads(status.stdout)["nodes"]}["recorder"]
        assert node["state"] == "error" and "No space left" in node["detail"], node
        assert ("spool of" in node["detail"]) == spool, node
        held = last_tick()
        time.sleep(1.0)
        assert last_tick() == held, "the clock did not hold for the recorder"
        assert launcher.supervisor.pids() == pids  # nothing stopped or restarted
        assert all(sv.state is ProcState.RUNNING for sv in launcher.supervisor.procs.values())
        (small_disk / "fill").unlink()
        wait_until(lambda: recorder_state() is NodeState.READY, 10.0, "recording again")
        wait_until(lambda: last_tick() >= held + 200, 120.0, "200 ticks after the hold")
        assert launcher.supervisor.pids() == pids
    finally:
        for sub in subs:
            sub.undeclare()
        launcher.stop()
    assert (small_disk / "recording.1.mcap").exists()
    recording = Recording.open(out)
    (gap,) = recording.gaps()
    assert gap.previous_segment == "recording.mcap" and "No space left" in gap.reason, gap
    recorded = [m.message().tick for m in recording.messages() if m.topic == keys.tick()]
    assert gap.first_tick is not None and gap.first_tick <= held + 1, (gap, held)
    # without the spool the open chunk is lost, less the physics's last 256 ticks re-sent
    assert gap.ticks_missing is not None and (
        gap.ticks_missing == 0 if spool else gap.ticks_missing >= 0
    ), gap
    assert max(recorded) >= held + 150, (held, max(recorded))
    # what the gap record says, measured on the segments themselves: the ticks they lack
    absent = ticks_not_recorded(out, keys.tick())
    assert len(absent) == gap.ticks_missing, (len(absent), absent[:3], absent[-3:], gap)
    assert "recorder reports an error: write error" in caplog.text
    print(f"\nfull at tick {filled_at}, held at {held}: {gap}")
