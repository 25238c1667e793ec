"""Nothing lost when a process dies (lockstep): SIGKILL of an autopilot while its vehicle flies
a mission, and of the physics and that autopilot at once, under the launcher that ``plumeswarm
up`` runs (router, plume, physics, three autopilots). The physics holds the clock while the
autopilot is restarted, the new autopilot restores the state of the tick before and flies on:
every vehicle's state stream is bit-identical to a run without the kill, the killed vehicle
finishes its mission and lands; every plume reading is the same too.

The missions start on a known tick, so that two runs can be compared bit for bit: a fourth
vehicle, parked on the ground, is a scripted lockstep participant that holds tick
``START_TICK`` until the test has armed the three and started their missions. The same flight
scales: N vehicles in a row, the gate the N + 1st (``tests/support/scale.py``).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import zenoh

from deploy.launcher import Launcher, LaunchOptions
from swarmbus.messages import (
    Arm,
    CommandReply,
    MissionStart,
)
from swarmbus.reqrep import request
from swarmbus.scenario import load_scenario
from swarmbus.session import free_tcp_port
from tests.support.flown import Flown
from tests.support.mavclient import write_scenario
from tests.support.procs import NODE_COMMAND, REPO, keys_for
from tests.support.scale import patience

VEHICLES = ("uav1", "uav2", "uav3")
GATE = "uav4"  # parked, scripted: holds START_TICK until the missions are started
START_TICK = 60
KILLED = "uav1"
# the physics' resume line: the checkpoint's tick and the last tick published before the kill
RESUMED = re.compile(
    r"resumed from checkpoint at tick (?P<tick>\d+) .*\(ticks \d+\.\.(?P<last>\d+)\)"
)


@dataclass
class ResumeRun(Flown):
    """A flight under the launcher: :meth:`wait` supervises (reaps and restarts) meanwhile, as
    ``up`` does."""

    launcher: Launcher = field(kw_only=True)

    def tend(self) -> None:
        self.launcher.supervise_once()

    def command(self, vid: str, cmd: object) -> CommandReply:
        key = self.launcher.keys.vehicle_cmd(vid)
        return request(self.launcher.session, key, cmd, CommandReply, 30.0)


def mission_scenario(path: Path, vehicles: tuple[str, ...], time_table: str = "") -> Path:
    """The test scenario of ``vehicles`` and the gate in a row, in ``path``, its start-up
    timeout stretched by :func:`patience`; ``time_table``: more lines of its ``[time]``."""
    write_scenario(path, len(vehicles) + 1)
    text = path.read_text()
    old = "startup_timeout_s = 60.0\n"
    assert old in text, "the seed scenario's start-up timeout moved"
    new = f"startup_timeout_s = {60.0 * patience(vehicles)}\n{time_table}"
    path.write_text(text.replace(old, new, 1))
    return path


@contextmanager
def flight(
    tmp: Path,
    per_process: int = 1,
    network_mode: str | None = None,
    vehicles: tuple[str, ...] = VEHICLES,
) -> Iterator[ResumeRun]:
    """The stack flying the missions of ``vehicles`` (uav1.. in a row) from tick START_TICK + 1
    on (``per_process`` vehicles per autopilot process; every node in ``network_mode``, default
    the scenario's)."""
    path = mission_scenario(tmp / "scenario.toml", vehicles)
    slow = patience(vehicles)
    if network_mode is not None:
        path.write_text(path.read_text() + f'\n[network]\nmode = "{network_mode}"\n')
    scenario = load_scenario(path)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        run_dir=tmp / "run",
        connect=(endpoint,),
        roles=("router", "plume", "physics", "autopilot"),
        vehicles=vehicles,
        vehicles_per_process=per_process,
    )
    launcher = Launcher(scenario, opts)
    gate_id = f"uav{len(vehicles) + 1}"
    f = ResumeRun(vehicles, gate_id, scenario.time.control_hz, launcher=launcher)
    subs: list[zenoh.Subscriber[None]] = []
    release = tmp / "release"

    def on_bus(session: zenoh.Session) -> None:  # before anything else runs: tick 0 on
        keys = keys_for()
        subs.append(session.declare_subscriber(keys.all_vehicle_states(), f.on_state))
        subs.append(session.declare_subscriber(keys.all_vehicle_status(), f.on_status))
        subs.append(session.declare_subscriber(keys.all_vehicle_concentration(), f.on_reading))

    gate: subprocess.Popen[bytes] | None = None
    try:
        launcher.start(on_bus)
        gate = subprocess.Popen(
            [sys.executable, "-m", "tests.support.scripted_participant", "--connect", endpoint,
             "--scenario", str(path), "--vehicle", gate_id, "--throttle", "0",
             "--delay-tick", str(START_TICK), "--delay-s", "300", "--release-file", str(release),
             "--follow-rewinds"],
            cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT,
        )  # fmt: skip
        f.wait(
            lambda: all(f.last_tick(v) >= START_TICK for v in (*vehicles, gate_id)),
            120.0 * slow,
            f"tick {START_TICK}",
        )
        for vid in vehicles:
            for cmd in (Arm(), MissionStart(start_index=0)):
                reply = f.command(vid, cmd)
                assert reply.accepted, (vid, cmd, reply.reason)
        assert all(f.last_tick(v) == START_TICK for v in vehicles), "the gate did not hold"
        release.touch()
        yield f
    finally:
        if gate is not None:
            with suppress(ProcessLookupError):
                os.killpg(gate.pid, signal.SIGTERM)
            gate.wait(10)
        for sub in subs:
            sub.undeclare()
        launcher.stop()


def fly_baseline(
    tmp: Path, per_process: int = 1, vehicles: tuple[str, ...] = VEHICLES
) -> ResumeRun:
    """The flight without any kill."""
    with flight(tmp, per_process, vehicles=vehicles) as f:
        f.wait(f.done, 300.0 * patience(vehicles), "every mission finished and landed")
        f.launcher.supervise_once()
        time.sleep(0.5)  # a few more ticks on the ground
    return f


@pytest.fixture(scope="module")
def baseline(tmp_path_factory: pytest.TempPathFactory) -> ResumeRun:
    """The flight without any kill."""
    return fly_baseline(tmp_path_factory.mktemp("baseline"))


def kill(f: ResumeRun, *names: str) -> None:
    pids = f.launcher.supervisor.pids()
    for name in names:
        os.killpg(pids[name], signal.SIGKILL)


def fly_with_kill(
    tmp: Path,
    *names: str,
    per_process: int = 1,
    network_mode: str | None = None,
    vehicles: tuple[str, ...] = VEHICLES,
) -> tuple[ResumeRun, int]:
    """Fly the missions, SIGKILL ``names`` while uav1 flies its first leg at 10 m; the flight
    and the last tick of uav1 seen before the kill."""
    with flight(tmp, per_process, network_mode, vehicles) as f:
        before = on_first_leg(f)
        old = f.launcher.supervisor.pids()
        kill(f, *names)
        f.wait(
            lambda: all(f.launcher.supervisor.pids().get(n) not in (None, old[n]) for n in names),
            120.0,
            f"{', '.join(names)} restarted",
        )
        f.wait(
            f.done,
            300.0 * patience(vehicles),
            "every mission finished and landed after the kill",
        )
        time.sleep(0.5)
    return f, before


def on_first_leg(f: Flown) -> int:
    """The last tick of :data:`KILLED` seen once it flies its first mission leg."""
    return f.on_first_leg(KILLED, 300.0 * patience(f.vehicles))


def assert_nothing_lost(f: Flown, baseline: Flown, killed_at: int) -> None:
    assert not f.conflicts, f"replayed ticks differ: {f.conflicts[:5]}"
    # the killed vehicle was flying at the kill, and flew on as it did without the kill: no
    # tick of it lower by more than 1 m than in the run without the kill ...
    assert f.z(KILLED, killed_at) > 8.0, f.z(KILLED, killed_at)
    common = sorted(set(f.states[KILLED]) & set(baseline.states[KILLED]))
    drop = max(baseline.z(KILLED, t) - f.z(KILLED, t) for t in common if t >= killed_at)
    assert drop < 1.0, drop
    # ... and every vehicle's state stream is the bits of the run without the kill
    assert (f.vehicles, f.gate) == (baseline.vehicles, baseline.gate)
    for vid in (*f.vehicles, f.gate):
        got, want = f.states[vid], baseline.states[vid]
        end = min(max(got), max(want))
        assert end > killed_at + 120 * 5, (vid, end)
        missing = [t for t in range(end + 1) if t not in got or t not in want]
        assert not missing, (vid, missing[:5])
        differ = [t for t in range(end + 1) if got[t] != want[t]]
        assert not differ, f"{vid}: {len(differ)} ticks differ from the run without the kill"
    # ... and so is every reading of the plume, through the kill (sensor state and queries)
    for vid in f.vehicles:
        got_r, want_r = f.readings[vid], baseline.readings[vid]
        end_s = min(max(got_r), max(want_r))
        times = sorted(t for t in set(got_r) | set(want_r) if t <= end_s)
        assert end_s > killed_at / 120.0 + 5.0, (vid, end_s)
        lost = [t for t in times if t not in got_r or t not in want_r]
        assert not lost, (vid, lost[:5])
        assert all(got_r[t] == want_r[t] for t in times), f"{vid}: readings differ"


def test_autopilot_killed_mid_mission_the_clock_waits_and_nothing_is_lost(
    baseline: ResumeRun, tmp_path: Path
) -> None:
    f, killed_at = fly_with_kill(tmp_path, f"autopilot-{KILLED}")
    assert_nothing_lost(f, baseline, killed_at)
    run = f.launcher.run_dir
    assert "holding the clock for uav1" in (run / "physics.log").read_text()
    assert "restored the state of tick" in (run / f"autopilot-{KILLED}.log").read_text()


def test_physics_and_autopilot_killed_at_once_nothing_is_lost(
    baseline: ResumeRun, tmp_path: Path
) -> None:
    """The restarted autopilot restores its predecessor's state; the others rewind to the
    tick before the checkpoint's if they had answered a tick past it (docs/physics.md,
    "Checkpoints and restart")."""
    f, killed_at = fly_with_kill(tmp_path, "physics", f"autopilot-{KILLED}")
    assert_nothing_lost(f, baseline, killed_at)
    run = f.launcher.run_dir
    found = RESUMED.search((run / "physics.log").read_text())
    assert found, "no resume from a checkpoint in physics.log"
    k, last = int(found["tick"]), int(found["last"])
    # the new process: its predecessor's state of k - 1 (or of k, if it had answered k)
    assert f"for tick {k} (restarted process)" in (run / f"autopilot-{KILLED}.log").read_text()
    restored = f"restored the state of tick {k - 1} for tick {k}"
    for vid in (v for v in VEHICLES if v != KILLED):
        log = (run / f"autopilot-{vid}.log").read_text()
        # none flew the replay on from a later state (the autopilot logs it when it has none)
        assert "sim time went back" not in log, vid
        # Tick `last` went out only once every autopilot had answered `last - 1`: from
        # k + 2 on each had gone past k and must have rewound. A kill between the checkpoint
        # of k on disk and tick k + 1 reaching them leaves them at k, and tick k again gets
        # the answer they already gave (the kill lands at ticks 470-524: 480..481 in 1 of 14).
        if last >= k + 2:
            assert restored + " (physics resumed from its checkpoint)" in log, (vid, k, last)


def test_a_process_of_two_autopilots_killed_both_vehicles_resume(
    baseline: ResumeRun, tmp_path: Path
) -> None:
    """Two vehicles in one process (one ActuatorBatch per tick): the clock holds both, the new
    process restores both, and the streams are the bits of the run without the kill (flown one
    vehicle per process: batching changes no bit either)."""
    f, killed_at = fly_with_kill(tmp_path, "autopilot-uav1-plus1", per_process=2)
    assert_nothing_lost(f, baseline, killed_at)
    log = (f.launcher.run_dir / "physics.log").read_text()
    assert "holding the clock for uav1, uav2: autopilot-uav1-plus1 is being restarted" in log
