"""The physics process over a real Zenoh network with scripted participants in other processes."""

from __future__ import annotations

import hashlib
import itertools
import json
import os
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path

import msgspec
import pytest
import zenoh

from agents import Swarm
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Clock,
    FieldSample,
    PlumeQuery,
    PlumeSample,
    PlumeValues,
    SimTick,
)
from swarmbus.reqrep import request
from swarmbus.session import Presence
from tests.support.procs import REPO, Network, NodeProcs, run_cli, wait_until

WORLD = "physics-test"
KEYS = Keys(WORLD)


def two_vehicle_scenario(
    tmp_path: Path,
    timeout_s: float = 1.0,
    startup_s: float = 60.0,
    name: str = "sc.toml",
    extra_time: str = "",
) -> Path:
    """Vehicles a (iris) and b (typhoon_h480) in world ``physics-test``; returns the path."""
    path = tmp_path / name
    path.write_text(
        f"""
[world]
name = "{WORLD}"
seed = 7
[time]
physics_hz = 240
control_hz = 120
participant_timeout_s = {timeout_s}
startup_timeout_s = {startup_s}
{extra_time}
[[vehicles]]
id = "a"
spawn_enu_m = [0.0, 0.0, 0.0]
[[vehicles]]
id = "b"
type = "typhoon_h480"
spawn_enu_m = [5.0, 0.0, 0.0]
"""
    )
    return path


def start_script(
    procs: NodeProcs, scenario: Path, *args: str, label: str
) -> subprocess.Popen[bytes]:
    """A scripted participant in its own process group, stopped with the node processes."""
    cmd = [
        sys.executable,
        "-m",
        "tests.support.scripted_participant",
        "--connect",
        procs.net.endpoint,
    ]
    cmd += ["--scenario", str(scenario), *args]
    assert procs.log_dir is not None
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    with open(procs.log_dir / f"{label}.log", "wb") as log:  # the child keeps its own descriptor
        proc = subprocess.Popen(
            cmd, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )
    procs.procs.append((label, proc))
    return proc


class Watch:
    """Every ``sim/tick`` and ``sim/clock`` seen by the test's own (router) session."""

    def __init__(self, session: zenoh.Session) -> None:
        self.lock = threading.Lock()
        self.raw: dict[int, bytes] = {}
        self.motors: dict[int, dict[str, bool]] = {}
        self.last_tick = -1
        self.clock: Clock | None = None
        self.session = session
        self._subs = [
            session.declare_subscriber(KEYS.tick(), self._on_tick),
            session.declare_subscriber(KEYS.clock(), self._on_clock),
        ]

    def _on_tick(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        msg = decode(data, SimTick)
        with self.lock:
            self.raw[msg.tick] = data
            self.motors[msg.tick] = {s.vehicle_id: s.motors_enabled for s in msg.states}
            self.last_tick = max(self.last_tick, msg.tick)

    def _on_clock(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.clock = decode(sample.payload.to_bytes(), Clock)

    def first_tick_after(self, tick: int, vid: str, enabled: bool) -> int:
        """The first tick after ``tick`` with ``vid``'s motors ``enabled``; 0 if none yet."""
        with self.lock:
            hits = [k for k, m in self.motors.items() if k > tick and m.get(vid) is enabled]
        return min(hits) if hits else 0

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def report(path: Path) -> dict[str, object]:
    data: dict[str, object] = json.loads(path.read_text())
    return data


def exit_code(proc: subprocess.Popen[bytes], what: str, timeout_s: float = 60.0) -> int:
    try:
        return proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"{what} did not exit within {timeout_s} s") from None


@pytest.fixture
def setup(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> Iterator[tuple[NodeProcs, Watch]]:
    net, session = network
    watch = Watch(session)
    procs = NodeProcs(net, log_dir=tmp_path)
    yield procs, watch
    procs.stop_all()
    watch.close()


def test_lockstep_holds_while_a_participant_delays_its_answer(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=10.0)
    physics = procs.start("physics", "--scenario", str(sc), "--set", "max_ticks=60", name="physics")
    slow = start_script(
        procs, sc, "--vehicle", "a", "--throttle", "0.3", "--delay-tick", "30", "--delay-s",
        "1.0", "--max-tick", "60", "--report", str(tmp_path / "a.json"), label="script-a",
    )  # fmt: skip
    fast = start_script(
        procs, sc, "--vehicle", "b", "--throttle", "0.3", "--max-tick", "60",
        "--report", str(tmp_path / "b.json"), label="script-b",
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    assert exit_code(slow, "participant a") == 0
    assert exit_code(fast, "participant b") == 0
    ra, rb = report(tmp_path / "a.json"), report(tmp_path / "b.json")
    assert ra["violations"] == [] and rb["violations"] == []
    assert ra["answered"] == 60 and rb["answered"] == 60
    # While a sat on tick 30 for a second, no later tick was published.
    assert ra["delayed"] is True and ra["seen_while_delaying"] == []
    wait_until(lambda: watch.last_tick == 60, 10.0, "tick 60 at the test's subscriber")
    assert all(watch.motors[k] == {"a": True, "b": True} for k in range(1, 61))


def test_sigkilled_participant_is_dropped_others_go_on_and_a_restart_rejoins(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=1.0)
    procs.start("physics", "--scenario", str(sc), name="physics")
    victim = start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a")
    start_script(procs, sc, "--vehicle", "b", "--throttle", "0.2", label="script-b")
    wait_until(lambda: watch.last_tick >= 20, 60.0, "tick 20")
    procs.kill(victim)
    killed_at = watch.last_tick
    dropped = wait_until(
        lambda: watch.first_tick_after(killed_at, "a", False), 30.0, "a's motors to go off"
    )
    wait_until(lambda: watch.last_tick >= dropped + 100, 30.0, "100 more ticks without a")
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a2")
    back = wait_until(
        lambda: watch.first_tick_after(dropped, "a", True), 60.0, "a to be admitted again"
    )
    wait_until(lambda: watch.last_tick >= back + 20, 30.0, "ticks with a back in")
    wait_until(
        lambda: watch.clock is not None and watch.clock.participants == ["a", "b"],
        10.0,
        "sim/clock to list both participants",
    )


def test_stalled_participant_is_dropped_at_the_timeout_and_rejoins(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=0.5)
    procs.start("physics", "--scenario", str(sc), name="physics")
    start_script(
        procs, sc, "--vehicle", "a", "--throttle", "0.2", "--stall-at-tick", "20",
        "--stall-s", "2.0", label="script-a",
    )  # fmt: skip
    start_script(procs, sc, "--vehicle", "b", "--throttle", "0.2", label="script-b")
    dropped = wait_until(lambda: watch.first_tick_after(20, "a", False), 60.0, "a dropped")
    assert all(watch.motors[k]["a"] for k in range(1, 21))  # it answered those in time
    wait_until(lambda: watch.last_tick >= dropped + 50, 30.0, "ticks go on without a")
    wait_until(lambda: watch.first_tick_after(dropped, "a", True), 60.0, "a rejoined")


def test_late_joiner_is_admitted(setup: tuple[NodeProcs, Watch], tmp_path: Path) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=1.0)
    procs.start(
        "physics", "--scenario", str(sc), "--set", "wait_for_autopilots=false", name="physics"
    )
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a")
    wait_until(lambda: watch.first_tick_after(0, "a", True), 60.0, "a's motors on")
    joined_from = watch.last_tick
    assert watch.motors[joined_from]["b"] is False  # nobody flies b yet
    # Garbage, a command on another vehicle's key and a command without a token change nothing.
    watch.session.put(KEYS.autopilot_actuators("autopilot-b"), b"\x00garbage")
    for key_vid in ("a", "b"):
        cmd = ActuatorCommand(vehicle_id="b", tick=watch.last_tick, rotor_commands=[1.0] * 6)
        batch = ActuatorBatch(tick=cmd.tick, commands=[cmd])
        watch.session.put(KEYS.autopilot_actuators(f"autopilot-{key_vid}"), encode(batch))
    wait_until(lambda: watch.last_tick >= joined_from + 50, 30.0, "ticks go on")
    assert watch.first_tick_after(joined_from, "b", True) == 0
    start_script(procs, sc, "--vehicle", "b", "--throttle", "0.2", label="script-b")
    wait_until(lambda: watch.first_tick_after(joined_from, "b", True), 60.0, "b admitted")


def ticks_digest(watch: Watch, ticks: int) -> tuple[str, SimTick]:
    """The SHA-256 of the encoded ticks 0..``ticks`` seen, and the last one (waits for them)."""
    wait_until(lambda: len(watch.raw) == ticks + 1, 10.0, f"ticks 0..{ticks} at the subscriber")
    digest = hashlib.sha256()
    for k in range(ticks + 1):
        digest.update(watch.raw[k])
    return digest.hexdigest(), decode(watch.raw[ticks], SimTick)


def stream_hash(
    procs: NodeProcs, watch: Watch, sc: Path, ticks: int, label: str, *script_args: str
) -> str:
    with watch.lock:
        watch.raw.clear()
        watch.last_tick = -1
    physics = procs.start(
        "physics", "--scenario", str(sc), "--set", f"max_ticks={ticks}", name=f"physics-{label}"
    )
    script = start_script(
        procs, sc, "--vehicle", "a", "--vehicle", "b", "--altitude", "3.0",
        "--max-tick", str(ticks), *script_args, label=label,
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    assert exit_code(script, "participant") == 0
    digest, last = ticks_digest(watch, ticks)
    assert all(s.position_enu_m[2] > 1.0 for s in last.states), "vehicles should have climbed"
    return digest


def test_two_runs_of_the_same_scenario_give_identical_state_streams(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path)
    first = stream_hash(procs, watch, sc, 240, "run1")
    second = stream_hash(procs, watch, sc, 240, "run2")
    assert first == second


def test_one_batch_per_process_gives_the_state_stream_of_one_command_per_vehicle(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path)
    singles = stream_hash(procs, watch, sc, 240, "singles")
    batched = stream_hash(procs, watch, sc, 240, "batched", "--batch")
    assert singles == batched


def test_bad_entries_of_a_batch_are_dropped_and_logged(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=1.0)
    procs.start(
        "physics", "--scenario", str(sc), "--set", "wait_for_autopilots=false", name="physics"
    )
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", "--batch", label="script-a")
    wait_until(lambda: watch.first_tick_after(0, "a", True), 60.0, "a's motors on (a batch)")
    key = KEYS.autopilot_actuators("intruder")
    watch.session.put(key, b"\x00garbage")
    tick = watch.last_tick
    good = {"vehicle_id": "b", "tick": tick, "rotor_commands": [1.0] * 6}
    entries = [
        {**good, "vehicle_id": "zz"},  # unknown vehicle
        {**good, "tick": tick + 1},  # another tick than the batch's
        {**good, "rotor_commands": [1.5] * 6},  # out of range
        good,  # b has no token: not a participant, its command is ignored
    ]
    batch = {"schema": "actuator_batch/v1", "tick": tick, "commands": entries}
    watch.session.put(key, msgspec.msgpack.encode(batch))
    wait_until(lambda: watch.last_tick >= tick + 50, 30.0, "ticks go on")
    assert watch.first_tick_after(tick, "b", True) == 0
    log = wait_until(
        lambda: (text := (tmp_path / "physics.log").read_text()).count("ignoring") >= 4 and text,
        10.0,
        "four log lines",
    )
    assert "ignoring actuator batch on" in log
    assert "ignoring actuators for zz" in log
    assert f"ignoring actuators for b of tick {tick + 1} in the batch of tick {tick}" in log
    assert "ignoring entry 2 of the actuator batch" in log and "rotor_commands" in log
    start_script(procs, sc, "--vehicle", "b", "--throttle", "0.2", "--batch", label="script-b")
    wait_until(lambda: watch.first_tick_after(tick, "b", True), 60.0, "b admitted by a batch")


def test_a_one_vehicle_nodes_batch_commands_only_its_own_vehicle(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """b holds tick 20; a batch on a's own key carrying b's command for tick 20 must not
    answer for b (the tick stays held), while the same batch on a process key that is not one
    vehicle's (``autopilot-a-plus1``) does."""
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path, timeout_s=60.0)
    release = tmp_path / "release"
    procs.start("physics", "--scenario", str(sc), name="physics")
    start_script(procs, sc, "--vehicle", "a", "--throttle", "0.2", label="script-a")
    start_script(
        procs, sc, "--vehicle", "b", "--throttle", "0.2", "--delay-tick", "20",
        "--delay-s", "60", "--release-file", str(release), label="script-b",
    )  # fmt: skip
    wait_until(lambda: watch.last_tick >= 20, 60.0, "tick 20 published")
    forged = ActuatorCommand(vehicle_id="b", tick=20, rotor_commands=[1.0] * 6)
    batch = encode(ActuatorBatch(tick=20, commands=[forged]))
    for _ in range(3):  # counted each time, logged once
        watch.session.put(KEYS.autopilot_actuators("autopilot-a"), batch)
    log = tmp_path / "physics.log"
    wait_until(
        lambda: "ignoring actuators for b on" in log.read_text(), 30.0, "the dropped command"
    )
    assert watch.last_tick == 20, "b's tick was answered by a's batch"
    assert log.read_text().count("ignoring actuators for b on") == 1
    watch.session.put(KEYS.autopilot_actuators("autopilot-a-plus1"), batch)
    wait_until(lambda: watch.last_tick >= 21, 30.0, "a multi-vehicle node's batch answers b")
    release.touch()
    wait_until(lambda: watch.last_tick >= 60, 30.0, "ticks go on")


PACKED = ("a", "b", "c", "d")


def write_packing_scenario(tmp_path: Path) -> Path:
    """Four vehicles flown by autopilots and a scripted ``gate`` that holds tick 1."""
    path = tmp_path / "packing.toml"
    vehicles = "".join(
        f'[[vehicles]]\nid = "{v}"\ntype = "{"typhoon_h480" if v == "b" else "iris"}"\n'
        f"spawn_enu_m = [{5.0 * k}, 0.0, 0.0]\n"
        for k, v in enumerate([*PACKED, "gate"])
    )
    path.write_text(
        f'[world]\nname = "{WORLD}"\nseed = 7\n[time]\nphysics_hz = 240\ncontrol_hz = 120\n'
        f"participant_timeout_s = 30.0\nstartup_timeout_s = 60.0\n{vehicles}"
    )
    return path


class Answers:
    """The last tick each vehicle's actuators answered, singly or in a batch."""

    def __init__(self, session: zenoh.Session) -> None:
        self.lock = threading.Lock()
        self.tick: dict[str, int] = {}
        self._subs = [session.declare_subscriber(KEYS.all_autopilot_actuators(), self._on)]

    def _on(self, sample: zenoh.Sample) -> None:
        msg = decode(sample.payload.to_bytes(), ActuatorBatch)
        with self.lock:
            for cmd in msg.commands:
                self.tick[cmd.vehicle_id] = max(cmd.tick, self.tick.get(cmd.vehicle_id, -1))

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def packed_flight_hash(
    procs: NodeProcs, watch: Watch, sc: Path, per_process: int, tmp_path: Path
) -> str:
    """Arm and take off all four while the gate holds tick 1, fly 3 s; the SimTick stream's hash."""
    ticks = 360
    with watch.lock:
        watch.raw.clear()
        watch.last_tick = -1
    release = tmp_path / f"release-{per_process}"
    answers = Answers(watch.session)
    physics = procs.start(
        "physics",
        "--scenario",
        str(sc),
        "--set",
        f"max_ticks={ticks}",
        name=f"physics-{per_process}",
    )
    autopilots = [
        procs.start(
            "autopilot",
            "--scenario",
            str(sc),
            *[a for v in group for a in ("--vehicle", v)],
            name=f"autopilot-k{per_process}-{group[0]}",
        )
        for group in (PACKED[i : i + per_process] for i in range(0, len(PACKED), per_process))
    ]
    gate = start_script(
        procs, sc, "--vehicle", "gate", "--throttle", "0", "--delay-tick", "1",
        "--delay-s", "60", "--release-file", str(release), "--max-tick", str(ticks),
        label=f"gate-{per_process}",
    )  # fmt: skip
    try:
        wait_until(
            lambda: all(answers.tick.get(v, -1) >= 1 for v in PACKED), 120.0, "answers to tick 1"
        )
        assert watch.last_tick == 1  # the gate holds it
        with Swarm.connect(WORLD, [procs.net.endpoint], command_timeout_s=20.0) as sw:
            sw.wait_until(lambda: set(PACKED) <= set(sw.vehicles), 30.0, "the autopilots")
            for vid in PACKED:
                sw.command(vid).arm()
                sw.command(vid).takeoff(3.0)
        release.touch()
        assert exit_code(physics, "physics") == 0
        assert exit_code(gate, "gate") == 0
    finally:
        answers.close()
        for proc in autopilots:
            procs.kill(proc)
    presence = Presence(watch.session, KEYS)
    assert presence.wait_for(lambda alive: not any(n.startswith("autopilot-") for n in alive), 30)
    presence.close()
    digest, last = ticks_digest(watch, ticks)
    assert all(s.position_enu_m[2] > 1.0 for s in last.states if s.vehicle_id in PACKED)
    return digest


def test_four_vehicles_fly_identically_packed_in_one_process_or_one_process_each(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = write_packing_scenario(tmp_path)
    one_each = packed_flight_hash(procs, watch, sc, 1, tmp_path)
    packed = packed_flight_hash(procs, watch, sc, 4, tmp_path)
    assert one_each == packed


def ticks_with_a_plume(
    procs: NodeProcs, watch: Watch, scenario: Path, max_ticks: int
) -> list[SimTick]:
    """Once a plume's token is up: a physics with no autopilot run to ``max_ticks``; its ticks."""
    presence = Presence(watch.session, KEYS)
    assert presence.wait_for(lambda alive: "plume" in alive, 60.0), sorted(presence.alive)
    presence.close()
    physics = procs.start(
        "physics", "--scenario", str(scenario), "--set", f"max_ticks={max_ticks}",
        "--set", "wait_for_autopilots=false", name="physics",
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    count = max_ticks + 1
    wait_until(lambda: len(watch.raw) == count, 10.0, f"ticks 0..{max_ticks} at the subscriber")
    return [decode(watch.raw[k], SimTick) for k in range(count)]


def test_the_plume_service_samples_each_sensor_tick_and_the_next_tick_carries_it(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path)
    procs.start("plume", "--scenario", str(sc), name="plume")
    ticks = ticks_with_a_plume(procs, watch, sc, 20)
    assert all(t.plume_queried for t in ticks)  # sensor every tick in this scenario
    assert ticks[0].plume_values is None
    for prev, t in itertools.pairwise(ticks):
        assert t.plume_values is not None and t.plume_values.tick == prev.tick
        points = [s.position_enu_m for s in prev.states]
        expected = request(
            watch.session,
            KEYS.plume_concentration(),
            encode(PlumeQuery(points_enu_m=points, sim_time_s=prev.sim_time_s)),
            PlumeValues,
            10.0,
        ).values_g_m3
        assert t.plume_values.values_g_m3 == expected


class StandInPlume:
    """Plays the plume service on the test's session: its token, and on every tick of
    ``sim/sensor`` (every tick is a sensor tick in this scenario) a ``FieldSample`` of made-up
    values —
    after ``DELAY_S`` before the ticks in ``silent``, none for those, at once after them;
    counts queries on plume/concentration (the physics must send none) and notes the newest
    tick seen when each answer went out."""

    DELAY_S = 0.05

    def __init__(self, watch: Watch, silent: range) -> None:
        session = watch.session
        self.watch = watch
        self.silent = silent
        self.queries = 0
        self.seen_when_answered: dict[int, int] = {}
        self._pub = session.declare_publisher(KEYS.plume_sample())
        self._token = session.liveliness().declare_token(KEYS.node_health("plume"))
        self._sub = session.declare_subscriber(KEYS.sensor_tick(), self._on_tick)
        self._q = session.declare_queryable(KEYS.plume_concentration(), self._on_query)

    @staticmethod
    def values(tick: int) -> list[float]:
        return [tick + 0.25, tick + 0.5]

    def _on_tick(self, sample: zenoh.Sample) -> None:
        msg = decode(sample.payload.to_bytes(), SimTick)
        if msg.tick in self.silent:
            return
        if msg.tick < self.silent.start:
            threading.Event().wait(self.DELAY_S)
        with self.watch.lock:
            self.seen_when_answered[msg.tick] = self.watch.last_tick
        answer = FieldSample(
            tick=msg.tick, sim_time_s=msg.sim_time_s, values_g_m3=self.values(msg.tick)
        )
        self._pub.put(encode(answer))

    def _on_query(self, query: zenoh.Query) -> None:
        self.queries += 1

    def close(self) -> None:
        for entity in (self._sub, self._q, self._token, self._pub):
            entity.undeclare()


def test_the_clock_waits_for_the_plume_sample_asks_nothing_and_drops_a_silent_plume(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """The physics waits for the plume as for a participant: tick k + 1 carries exactly what
    the plume answered to tick k, and only after it answered; it never queries the plume. A
    plume silent past the participant timeout is dropped (that tick's values unavailable, no
    tick waits for it: with no autopilot the physics runs on at once) and, once it answers a
    tick again, every tick waits for it as before."""
    procs, watch = setup
    sc = two_vehicle_scenario(tmp_path)  # participant timeout 1 s
    plume = StandInPlume(watch, silent=range(5, 10))
    try:
        ticks = ticks_with_a_plume(procs, watch, sc, 400)
    finally:
        plume.close()
    assert plume.queries == 0
    waited = [t.tick for t in ticks if t.plume_queried]
    # 0..5 waited for (5 timed out), then none until it answered again; every one from then on
    back = waited[6]
    assert waited == [*range(0, 6), *range(back, 401)] and 10 < back < 400, waited
    for k in waited[:-1]:
        if k == 5:
            assert ticks[6].plume_values == PlumeSample(tick=5, values_g_m3=None)
            continue
        assert ticks[k + 1].plume_values == PlumeSample(tick=k, values_g_m3=plume.values(k))
        assert plume.seen_when_answered[k] <= k  # tick k + 1 was not out before the answer
    assert all(ticks[k].plume_values is None for k in range(7, back + 1))
    log = (tmp_path / "physics.log").read_text()
    assert "tick 5: no plume sample after 1.00 s" in log


def test_missing_autopilots_fail_start_up_naming_them(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, _ = setup
    sc = two_vehicle_scenario(tmp_path, startup_s=1.0)
    physics = procs.start("physics", "--scenario", str(sc), name="physics")
    assert exit_code(physics, "physics") == 1
    log = (tmp_path / "physics.log").read_text()
    assert "autopilots missing" in log and "a, b" in log and "autopilot-a" in log


def test_realtime_mode_with_a_duration_ends_at_that_sim_time(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = two_vehicle_scenario(
        tmp_path, extra_time='mode = "realtime"\nspeed_factor = 4.0\nduration_s = 1.0'
    )
    physics = procs.start(
        "physics", "--scenario", str(sc), "--set", "wait_for_autopilots=false", name="physics"
    )
    assert exit_code(physics, "physics") == 0
    wait_until(lambda: watch.last_tick == 120, 10.0, "tick 120 (1 s at 120 Hz)")
    wait_until(lambda: watch.clock is not None and watch.clock.tick == 120, 10.0, "final clock")
    assert watch.clock is not None and watch.clock.mode == "realtime"
    assert watch.clock.sim_time_s == pytest.approx(1.0)


def test_unknown_option_is_a_clear_error(tmp_path: Path) -> None:
    result = run_cli(
        ["node", "physics", "--scenario", str(two_vehicle_scenario(tmp_path)), "--set", "warp=9"]
    )
    assert result.returncode == 2
    assert "--set warp=9: unknown option; known: checkpoint," in result.stderr
