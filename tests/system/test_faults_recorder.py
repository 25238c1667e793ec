"""The recorder loses nothing (lockstep): SIGKILL of the recorder under the launcher that
``plumeswarm up --record`` runs (router, recorder, plume, physics, three autopilots on the
ground, ticking). The killed recorder's queue and open chunk are recovered from its write-ahead
spool (``recorder.spool``) by the restarted one; the physics holds the clock until it is back.
Counted against the test's own subscriber, which sees every tick: every ``sim/tick`` and every
``vehicle/<id>/state`` it saw between the first and the last tick recorded is in the recording
(both segments).
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Callable
from pathlib import Path

import zenoh

from deploy.launcher import Launcher
from recorder.reader import Recording
from swarmbus.codec import decode
from swarmbus.messages import SimTick, VehicleState
from swarmbus.scenario import load_scenario
from swarmbus.session import free_tcp_port
from tests.support.mavclient import write_scenario
from tests.support.procs import keys_for, wait_until
from tests.support.upstack import recording_launch

VEHICLES = ("uav1", "uav2", "uav3")


def test_recorder_killed_nothing_it_received_is_lost(tmp_path: Path) -> None:
    path, _, _ = write_scenario(tmp_path / "scenario.toml", len(VEHICLES))
    scenario = load_scenario(path)
    opts = recording_launch(path, tmp_path / "run", f"tcp/127.0.0.1:{free_tcp_port()}")
    keys = keys_for()
    lock = threading.Lock()
    seen: dict[tuple[str, int], bytes] = {}  # (key, tick) → payload, as the test received it

    def on_sample(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        key = str(sample.key_expr)
        msg = decode(payload, SimTick) if key == keys.tick() else decode(payload, VehicleState)
        tick = msg.tick
        with lock:
            seen.setdefault((key, tick), payload)

    subs: list[zenoh.Subscriber[None]] = []

    def on_bus(session: zenoh.Session) -> None:
        subs.append(session.declare_subscriber(keys.tick(), on_sample))
        subs.append(session.declare_subscriber(keys.all_vehicle_states(), on_sample))

    launcher = Launcher(scenario, opts)

    def last_tick() -> int:
        with lock:
            return max((t for k, t in seen if k == keys.tick()), default=-1)

    def supervised(predicate: Callable[[], bool]) -> Callable[[], bool]:
        def check() -> bool:
            launcher.supervise_once()
            return predicate()

        return check

    try:
        launcher.start(on_bus)
        wait_until(supervised(lambda: last_tick() >= 600), 120.0, "600 ticks")
        old = launcher.supervisor.pids()["recorder"]
        killed_at = last_tick()
        os.killpg(old, signal.SIGKILL)
        wait_until(
            supervised(lambda: launcher.supervisor.pids()["recorder"] != old), 60.0, "restart"
        )
        wait_until(supervised(lambda: last_tick() >= killed_at + 600), 120.0, "600 more ticks")
    finally:
        for sub in subs:
            sub.undeclare()
        launcher.stop()
    run = opts.run_dir
    assert (run / "recording.1.mcap").exists()
    recorded: dict[tuple[str, int], bytes] = {}
    for m in Recording.open(run / "recording.mcap").messages():
        if m.topic == keys.tick() or m.topic.endswith("/state"):
            msg = m.message()
            tick = getattr(msg, "tick", None)
            if isinstance(tick, int):
                recorded.setdefault((m.topic, tick), m.data)
    ticks = sorted(t for k, t in recorded if k == keys.tick())
    first, last = ticks[0], ticks[-1]
    assert first < killed_at < last - 100, (first, killed_at, last)
    with lock:
        wanted = {kt for kt in seen if first <= kt[1] <= last}
    missing = sorted(wanted - recorded.keys(), key=lambda kt: (kt[1], kt[0]))
    print(f"\nrecorder killed at tick {killed_at}: recorded ticks {first}..{last}, "
          f"{len(wanted)} tick and state messages seen by the test, {len(missing)} missing "
          f"from the recording: {missing[:10]}")  # fmt: skip
    assert not missing
    log = (run / "recorder.log").read_text()
    assert "recovered" in log, "nothing recovered from the spool"
