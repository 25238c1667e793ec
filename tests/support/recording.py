"""Recording a run of the scripted publisher (tests/support/scripted_publisher.py): the
publisher and recorder processes, and what the publisher says it published; the ticks a
recording lacks."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from recorder.reader import Recording
from swarmbus.messages import SimTick
from tests.support.procs import REPO, Network, NodeProcs


def start_publisher(
    net: Network, out: Path, *args: str, env: Mapping[str, str] | None = None
) -> subprocess.Popen[str]:
    """The scripted publisher (``env`` added to this process's environment)."""
    environ = dict(os.environ, PYTHONPATH=str(REPO), **(env or {}))
    cmd = [sys.executable, "-m", "tests.support.scripted_publisher", "--connect", net.endpoint]
    return subprocess.Popen(
        [*cmd, "--out", str(out), *args],
        cwd=REPO,
        env=environ,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def finish_publisher(
    proc: subprocess.Popen[str], out: Path, timeout_s: float = 90.0
) -> dict[str, Any]:
    """Wait for a scripted publisher; its counts and published payloads."""
    try:
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    assert proc.returncode == 0, f"scripted publisher failed:\n{err[-3000:]}"
    result: dict[str, Any] = json.loads(out.read_text())
    return result


def run_publisher(
    net: Network, out: Path, *args: str, env: Mapping[str, str] | None = None
) -> dict[str, Any]:
    """Run the scripted publisher to completion."""
    return finish_publisher(start_publisher(net, out, *args, env=env), out)


def start_recorder(procs: NodeProcs, out: Path, *extra: str) -> subprocess.Popen[bytes]:
    return procs.start("recorder", "--set", f"out={out}", *extra, name="recorder")


def recorded_run(net: Network, log_dir: Path, out: Path, *publisher_args: str) -> dict[str, Any]:
    """Record ``out`` while the scripted publisher runs with ``publisher_args`` to its end,
    then stop the recorder, which must exit cleanly; the publisher's result."""
    with NodeProcs(net, log_dir=log_dir) as procs:
        rec = start_recorder(procs, out)
        published = run_publisher(net, log_dir / "pub.json", *publisher_args)
        procs.stop_all()
    assert rec.returncode == 0, (log_dir / "recorder.log").read_text()[-3000:]
    return published


def published_messages(published: dict[str, Any]) -> list[tuple[str, bytes]]:
    """(key, payload) of every message the publisher put, in order."""
    return [(key, bytes.fromhex(payload)) for key, payload, _ in published["published"]]


def ticks_not_recorded(path: Path, tick_key: str) -> list[int]:
    """The ticks between the first and the last ``SimTick`` on ``tick_key`` that no segment of
    the recording at ``path`` holds (read from the messages, not from a gap record)."""
    ticks = {
        msg.tick
        for m in Recording.open(path).messages()
        if m.topic == tick_key and isinstance(msg := m.message(), SimTick)
    }
    assert ticks, f"no tick on {tick_key} in {path}"
    return sorted(set(range(min(ticks), max(ticks) + 1)) - ticks)
