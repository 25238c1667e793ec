"""The physics process's commands in batches and its determinism: the same scenario gives the
same tick stream twice, whether commands come one per vehicle or one batch per process, and
vehicles packed in one autopilot process fly as in one process each; a batch's bad entries and
a batch on one vehicle's key commanding another are dropped."""

from __future__ import annotations

import threading
from pathlib import Path

import msgspec
import pytest
import zenoh

from agents import Swarm
from swarmbus.codec import decode, encode
from swarmbus.messages import ActuatorBatch, ActuatorCommand
from swarmbus.session import Presence
from tests.support.physics_rig import (
    KEYS,
    WORLD,
    Watch,
    climbed_digest,
    exit_code,
    start_script,
    stream_hash,
    two_vehicle_scenario,
    vehicles_toml,
)
from tests.support.procs import NodeProcs, wait_until


@pytest.mark.parametrize(
    "second_args",
    [(), ("--batch",)],
    ids=["the-same-run-twice", "one-batch-per-process-against-one-command-per-vehicle"],
)
def test_the_same_scenario_gives_identical_state_streams(
    rig: tuple[NodeProcs, Watch], tmp_path: Path, second_args: tuple[str, ...]
) -> None:
    """Two runs of one scenario, the second with ``second_args`` for its participant: the same
    tick stream, bit for bit (with ``--batch`` it sends one batch per process instead of one
    command per vehicle)."""
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path)
    first = stream_hash(procs, watch, sc, 240, "first")
    second = stream_hash(procs, watch, sc, 240, "second", *second_args)
    assert first == second


def test_bad_entries_of_a_batch_are_dropped_and_logged(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
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
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """b holds tick 20; a batch on a's own key carrying b's command for tick 20 must not
    answer for b (the tick stays held), while the same batch on a process key that is not one
    vehicle's (``autopilot-a-plus1``) does."""
    procs, watch = rig
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
    vehicles = vehicles_toml(
        *((v, "typhoon_h480" if v == "b" else "iris", (5.0 * k, 0.0, 0.0))
          for k, v in enumerate([*PACKED, "gate"]))
    )  # fmt: skip
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
    watch.forget()
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
    return climbed_digest(watch, ticks, PACKED)


def test_four_vehicles_fly_identically_packed_in_one_process_or_one_process_each(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = write_packing_scenario(tmp_path)
    one_each = packed_flight_hash(procs, watch, sc, 1, tmp_path)
    packed = packed_flight_hash(procs, watch, sc, 4, tmp_path)
    assert one_each == packed
