"""The fused runner against the distributed stack: the same state stream, bit for bit.

Both sides get the same scenario and the same commands at the same tick boundaries. The
distributed side is held between ticks either by the stepped clock (``time.mode = "stepped"``,
stepped by a ``Swarm`` client: the scenario itself, unchanged) or by a clock holder in the test
process (a parked extra vehicle's lockstep participant, tests/support/clock_holder.py: the plain
lockstep, without the stepped clock's code). Each side's digest covers every vehicle's state of
every tick from 0.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from functools import partial
from pathlib import Path

import pytest
import zenoh

from agents import CommandRejected, CommandTimeout, Swarm, VehicleCommander
from plumeswarm.experiments.demo import StateDigest
from plumeswarm.experiments.fused import FusedRunner
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    Command,
    CommandReply,
    FlightMode,
    LinkStatus,
    MissionStart,
    PlumeQuery,
    PlumeValues,
    SetMode,
    SimTick,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.scenario import DEFAULT_SCENARIO, Scenario, load_scenario
from tests.support.clock_holder import ClockHolder
from tests.support.procs import NodeProcs, wait_for_queryable, wait_until, zenoh_network

CLOCK = "clock"
FLYERS = ("uav1", "uav2", "uav3")
CLOCK_VEHICLE = f"""
[[vehicles]]
id = "{CLOCK}"
spawn_enu_m = [-300.0, 0.0, 0.0]
"""
ONE_EACH = (("uav1",), ("uav2",), ("uav3",))  # one autopilot process per flyer
BEHAVIOUR = 'behavior = "agents.behaviors.casting:Casting"\n'

Boundary = dict[int, list[tuple[str, Command]]]


def default_with_clock(tmp_path: Path, noisy_casting: bool = False) -> Path:
    """The default scenario and a parked vehicle far upwind whose participant holds the clock;
    ``noisy_casting``: every flyer has the casting behaviour and the sensor is noisy and slow."""
    text = DEFAULT_SCENARIO.read_text()
    if noisy_casting:
        text = text.replace("noise_std_g_m3 = 0.0", "noise_std_g_m3 = 0.02")
        text = text.replace("time_constant_s = 0.0", "time_constant_s = 0.3")
        text = text.replace('type = "iris"\n', f'type = "iris"\n{BEHAVIOUR}')
    path = tmp_path / "scenario.toml"
    path.write_text(text + CLOCK_VEHICLE)
    return path


def fused_stream(
    scenario: Scenario,
    last_tick: int,
    boundary: Boundary,
    after_step: Callable[[FusedRunner], None] | None = None,
) -> tuple[dict, FusedRunner]:
    digest = StateDigest()
    maxima: dict[str, float] = {}

    def observe(states: Sequence[VehicleState]) -> None:
        for s in states:
            digest.add(encode(s))
            maxima[s.vehicle_id] = max(maxima.get(s.vehicle_id, 0.0), s.position_enu_m[2])

    runner = FusedRunner(scenario, on_states=observe)
    for k in range(last_tick + 1):
        for vid, command in boundary.get(k, []):
            reply = runner.command(vid, command)
            assert reply.accepted, (k, vid, command, reply)
        if k < last_tick:
            runner.step()
            if after_step is not None:
                after_step(runner)
    assert all(maxima[v] > 5.0 for v in FLYERS), f"the flyers should have climbed: {maxima}"
    return digest.result(), runner


def start_plume_and_autopilots(
    procs: NodeProcs,
    session: zenoh.Session,
    keys: Keys,
    groups: Sequence[Sequence[str]] = ONE_EACH,
) -> None:
    """The plume first and answering (the first sensor ticks must find it), then the flyers
    (one autopilot process per group)."""
    start_plume(procs, session, keys)
    for group in groups:
        procs.start("autopilot", *(a for v in group for a in ("--vehicle", v)))


def start_plume(procs: NodeProcs, session: zenoh.Session, keys: Keys) -> None:
    """The plume service, answering."""
    procs.start("plume")
    wait_for_queryable(
        session,
        keys.plume_concentration(),
        PlumeQuery(points_enu_m=[(30.0, 0.0, 10.0)], sim_time_s=0.0),
        PlumeValues,
        60.0,
        "the plume service",
    )


def distributed_stream(
    path: Path,
    scenario: Scenario,
    last_tick: int,
    boundary: Boundary,
    log_dir: Path,
    groups: Sequence[Sequence[str]] = ONE_EACH,
) -> dict:
    keys = Keys(scenario.world.name)
    with zenoh_network() as (net, session), NodeProcs(net, path, log_dir) as procs:
        start_plume_and_autopilots(procs, session, keys, groups)
        holder = ClockHolder(session, keys, CLOCK, FLYERS, rotor_count=4)
        try:
            procs.start("physics")
            holder.run(last_tick, lambda k: boundary.get(k, []))
            return holder.digest.result()
        finally:
            holder.close()


def stepped_stream(
    path: Path, scenario: Scenario, last_tick: int, boundary: Boundary, log_dir: Path
) -> dict:
    """The distributed stack in stepped mode, stepped by a Swarm client between boundaries
    (one autopilot process per vehicle of the scenario)."""
    keys = Keys(scenario.world.name)
    digest = StateDigest()

    def on_tick(sample: zenoh.Sample) -> None:
        for state in decode(sample.payload.to_bytes(), SimTick).states:
            digest.add(encode(state))

    with zenoh_network() as (net, session), NodeProcs(net, path, log_dir) as procs:
        sub = session.declare_subscriber(keys.tick(), on_tick)
        start_plume_and_autopilots(procs, session, keys, [(v.id,) for v in scenario.vehicles])
        procs.start("physics")
        with Swarm.connect(scenario.world.name, [net.endpoint], command_timeout_s=20.0) as sw:
            tick = 0
            for k in sorted(boundary):
                if k > tick:
                    tick = sw.step(k - tick).tick
                for vid, command in boundary[k]:
                    # paused at tick k: an autopilot that has not seen tick 0 yet refuses (no
                    # state), and nothing moves until the next step however long this takes
                    reply = wait_until(
                        partial(_accepted, session, keys, vid, command),
                        60.0,
                        f"{vid} to accept {command}",
                    )
                    assert reply.accepted
            if last_tick > tick:
                sw.step(last_tick - tick)
        sub.undeclare()
    return digest.result()


def _accepted(
    session: zenoh.Session, keys: Keys, vid: str, command: Command
) -> CommandReply | None:
    try:
        return VehicleCommander(session, keys, vid, 5.0).send(command)
    except CommandTimeout:
        return None
    except CommandRejected as exc:
        if "no vehicle state" in exc.reason:
            return None
        raise AssertionError(f"{vid} refused {command}: {exc.reason}") from None


def stepped_scenario(tmp_path: Path, noisy_casting: bool = False) -> Path:
    """The default scenario (or its casting variant) on the stepped clock, nothing added."""
    text = default_with_clock(tmp_path, noisy_casting).read_text().replace(CLOCK_VEHICLE, "")
    text = text.replace('mode = "lockstep"', 'mode = "stepped"')
    path = tmp_path / "stepped.toml"
    path.write_text(text)
    assert load_scenario(path).time.mode == "stepped"
    return path


def assert_same_stream(
    tmp_path: Path,
    path: Path,
    last_tick: int,
    boundary: Boundary,
    stepped: bool,
    after_step: Callable[[FusedRunner], None] | None = None,
) -> FusedRunner:
    scenario = load_scenario(path)
    fused, runner = fused_stream(scenario, last_tick, boundary, after_step)
    run = stepped_stream if stepped else distributed_stream
    distributed = run(path, scenario, last_tick, boundary, tmp_path)
    runner.close()
    vehicles = len(scenario.vehicles)
    assert fused["messages"] == distributed["messages"] == (last_tick + 1) * vehicles
    assert distributed["missing"] == distributed["conflicts"] == 0
    assert fused["sha256"] == distributed["sha256"]
    return runner


CLOCKS = pytest.mark.parametrize("clock", ["stepped", "holder"])


def scenario_for(tmp_path: Path, clock: str, noisy_casting: bool = False) -> Path:
    if clock == "stepped":
        return stepped_scenario(tmp_path, noisy_casting)
    return default_with_clock(tmp_path, noisy_casting)


@CLOCKS
def test_default_scenario_missions_give_the_same_states_fused_and_distributed(
    tmp_path: Path, clock: str
) -> None:
    boundary: Boundary = {0: [(v, c) for v in FLYERS for c in (Arm(), MissionStart())]}
    path = scenario_for(tmp_path, clock)
    assert_same_stream(tmp_path, path, 1200, boundary, stepped=clock == "stepped")


@CLOCKS
def test_casting_in_offboard_with_a_noisy_sensor_gives_the_same_states(
    tmp_path: Path, clock: str
) -> None:
    # Casting has no collision avoidance and every flyer homes in on the same plume axis: each
    # holds its own altitude, 2 m apart (the offboard switch waits for the highest take-off),
    # so that whichever the noise, the behaviours fly on instead of into each other.
    altitude_m = {"uav1": 8.0, "uav2": 10.0, "uav3": 12.0}
    boundary: Boundary = {
        0: [(v, c) for v in FLYERS for c in (Arm(), Takeoff(altitude_m=altitude_m[v]))],
        600: [(v, SetMode(mode=FlightMode.OFFBOARD)) for v in FLYERS],
    }
    path = scenario_for(tmp_path, clock, noisy_casting=True)
    runner = assert_same_stream(tmp_path, path, 1440, boundary, stepped=clock == "stepped")
    # Not a vacuous comparison: the behaviours flew on noisy readings of real gas.
    for vid in FLYERS:
        assert runner.flights[vid].autopilot.modes.mode == FlightMode.OFFBOARD, vid
    readings = [r for r in runner.latest_readings.values() if r.true_g_m3 is not None]
    assert readings and any(r.reported_g_m3 != r.true_g_m3 for r in readings)


def test_a_fixed_wing_take_off_gives_the_same_states_fused_and_distributed(
    tmp_path: Path,
) -> None:
    """The Aerosonde's ground roll, rotation and climb-out (12 s) over the bus, stepped."""
    path = tmp_path / "plane.toml"
    path.write_text(
        '[world]\nname = "plane"\n[time]\nphysics_hz = 240\ncontrol_hz = 120\n'
        'mode = "stepped"\n[wind]\nspeed_m_s = 3.0\nfrom_deg = 270.0\n'
        "[failsafe]\ntakeoff_altitude_m = 30.0\n"
        '[[vehicles]]\nid = "p"\ntype = "aerosonde"\nspawn_enu_m = [0.0, 0.0, 0.0]\n'
    )
    scenario = load_scenario(path)
    last_tick = 12 * 120
    boundary: Boundary = {0: [("p", Arm()), ("p", Takeoff(altitude_m=30.0))]}
    digest = StateDigest()
    top = 0.0
    with FusedRunner(scenario) as runner:
        for vid, command in boundary[0]:
            assert runner.command(vid, command).accepted
        for s in runner.states:
            digest.add(encode(s))
        for _ in range(last_tick):
            for s in runner.step():
                digest.add(encode(s))
                top = max(top, s.position_enu_m[2])
    assert top > 20.0, "the plane should have taken off"
    fused = digest.result()
    distributed = stepped_stream(path, scenario, last_tick, boundary, tmp_path)
    assert fused["messages"] == distributed["messages"] == last_tick + 1
    assert distributed["missing"] == distributed["conflicts"] == 0
    assert fused["sha256"] == distributed["sha256"]


def test_the_docs_example_of_the_runner_flies_the_missions() -> None:
    text = (Path(__file__).resolve().parents[2] / "docs" / "envs.md").read_text()
    section = text.split("## The fused runner without an environment", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    scope: dict[str, object] = {}
    exec(code, scope)
    states = scope["states"]
    assert isinstance(states, list) and len(states) == 3
    # 10 s after the start the missions' take-off to 10 m is done and the legs are being flown
    assert all(abs(s.position_enu_m[2] - 10.0) < 1.0 for s in states)


COOP = 'behavior = "agents.behaviors.coop_surge_cast:CooperativeSurgeCast"\n'
LOSSY_RADIO = "\n[radio]\nloss = 0.3\nlatency_ticks = 3\n"


def coop_over_lossy_radio(tmp_path: Path, clock: str) -> tuple[Path, Scenario, Boundary]:
    """The casting scenario's flyers as cooperative surge-casters over a lossy, slow radio:
    take-off to 8, 10 and 12 m, offboard at tick 600. The sensor is noisy but without lag: a
    lagging one gets the rise detector, whose threshold (3·√2 of the noise) this plume's
    readings at these heights never rise by in one sample, and nothing would be shared."""
    path = scenario_for(tmp_path, clock, noisy_casting=True)
    text = path.read_text().replace("time_constant_s = 0.3", "time_constant_s = 0.0")
    path.write_text(text.replace(BEHAVIOUR, COOP) + LOSSY_RADIO)
    altitude_m = {"uav1": 8.0, "uav2": 10.0, "uav3": 12.0}
    boundary: Boundary = {
        0: [(v, c) for v in FLYERS for c in (Arm(), Takeoff(altitude_m=altitude_m[v]))],
        600: [(v, SetMode(mode=FlightMode.OFFBOARD)) for v in FLYERS],
    }
    return path, load_scenario(path), boundary


@CLOCKS
def test_talking_behaviours_over_a_lossy_radio_give_the_same_states(
    tmp_path: Path, clock: str
) -> None:
    # Three cooperative surge-casters share their detections over a radio that loses 30 % of
    # every message (peer states, peer samples, detections) and delays each by 3 ticks: the
    # distributed processes decide every delivery as the fused runner does.
    path, scenario, boundary = coop_over_lossy_radio(tmp_path, clock)
    assert scenario.radio.loss == 0.3 and scenario.radio.latency_ticks == 3
    received: list[int] = []

    def count_inbox(runner: FusedRunner) -> None:
        received.append(sum(len(runner.link.mailboxes[v].inbox) for v in FLYERS))

    runner = assert_same_stream(
        tmp_path, path, 1440, boundary, stepped=clock == "stepped", after_step=count_inbox
    )
    # Not a vacuous comparison: detections went over the radio and arrived, some were lost.
    assert sum(received) > 0
    messages = [(s, r) for (s, r) in runner.link.counts if s in FLYERS and r in FLYERS]
    dropped = sum(runner.link.counts[link].dropped for link in messages)
    delivered = sum(runner.link.counts[link].delivered for link in messages)
    assert dropped > 0 and abs(dropped / (dropped + delivered) - 0.3) < 0.02


def test_talking_behaviours_served_two_by_one_process_give_the_same_states(
    tmp_path: Path,
) -> None:
    """uav1 and uav2 in one autopilot process (their messages to each other never leave it),
    uav3 in another: the same state stream as the fused runner."""
    path, scenario, boundary = coop_over_lossy_radio(tmp_path, "holder")
    fused, runner = fused_stream(scenario, 1200, boundary)
    runner.close()
    groups = (("uav1", "uav2"), ("uav3",))
    distributed = distributed_stream(path, scenario, 1200, boundary, tmp_path, groups)
    assert distributed["missing"] == distributed["conflicts"] == 0
    assert fused["sha256"] == distributed["sha256"]


def _alive(session: zenoh.Session, key: str) -> bool:
    return any(r.ok is not None for r in session.liveliness().get(key, timeout=2.0))


def _gone(session: zenoh.Session, key: str) -> bool:
    return not _alive(session, key)


def test_a_restarted_talking_autopilot_carries_on_with_the_same_bits(tmp_path: Path) -> None:
    """uav1's autopilot is killed while the clock holds a tick of the offboard flight (a peer's
    message to it in flight over a lossy, slow radio) and restarted from its checkpoint: the
    state stream is still the fused runner's, bit for bit (its link came back with it, and the
    peers' messages of the tick it missed were asked of them)."""
    path, scenario, boundary = coop_over_lossy_radio(tmp_path, "holder")
    last_tick, killed = 1200, "uav1"
    heard_at: list[int] = []  # the ticks at which uav1's behaviour got peers' messages
    counted: dict[int, list[LinkStatus]] = {}  # what the links into uav1 carried, by tick

    def note(runner: FusedRunner) -> None:
        if runner.link.mailboxes[killed].inbox:
            heard_at.append(runner.tick)
        counted[runner.tick] = runner.link.link_status(killed)

    fused, runner = fused_stream(scenario, last_tick, boundary, note)
    runner.close()
    # killed two ticks before it hears a message: the message (sent 4 ticks before it is
    # heard) is in flight at the kill, and only the checkpoint's link holds it
    kill_at = next(t for t in heard_at if t >= 700) - 2
    assert kill_at < last_tick - 100, heard_at
    keys = Keys(scenario.world.name)
    checkpoint = tmp_path / f"autopilot-{killed}.ckpt"
    token = keys.node_health(f"autopilot-{killed}")
    statuses: list[VehicleStatus] = []
    last_s = (last_tick - scenario.time.control_hz) / scenario.time.control_hz  # the last second
    with zenoh_network() as (net, session), NodeProcs(net, path, tmp_path) as procs:
        on_status = partial(_keep_status, statuses)
        sub = session.declare_subscriber(keys.vehicle_status(killed), on_status)
        start_plume(procs, session, keys)
        ap = {}
        for vid in FLYERS:
            extra = ["--set", f"checkpoint={checkpoint}"] if vid == killed else []
            ap[vid] = procs.start("autopilot", "--vehicle", vid, *extra, name=f"autopilot-{vid}")
        holder = ClockHolder(session, keys, CLOCK, FLYERS, rotor_count=4)
        try:
            procs.start("physics")
            for k in range(last_tick + 1):
                holder.wait_answered(k, 60.0)
                for vid, command in boundary.get(k, []):
                    assert VehicleCommander(session, keys, vid, 5.0).send(command).accepted
                if k == kill_at:
                    procs.kill(ap[killed])
                    wait_until(partial(_gone, session, token), 30.0, "the token gone")
                    again = f"autopilot-{killed}-again"
                    procs.start("autopilot", "--vehicle", killed, "--set",
                                f"checkpoint={checkpoint}", name=again)  # fmt: skip
                    wait_until(partial(_alive, session, token), 60.0, "the restarted")
                if k < last_tick:
                    holder.release(k)
            distributed = holder.digest.result()
            wait_until(partial(_status_of, statuses, last_s), 30.0, "a last status")
        finally:
            holder.close()
            sub.undeclare()
    log = (tmp_path / f"autopilot-{killed}-again.log").read_text()
    assert "restored the state of tick" in log
    assert "stepping without" not in log  # it had every peer's messages of every tick
    assert fused["messages"] == distributed["messages"] == (last_tick + 1) * 4
    assert distributed["missing"] == distributed["conflicts"] == 0
    assert fused["sha256"] == distributed["sha256"]
    # Its status counts what the links into it carried over the whole run, the kill included
    # (the checkpoint kept the counts): the tick's peer states and samples are counted when
    # it steps, the behaviours' messages of a tick on the next, so the counts lie between
    # the fused runner's after tick - 1 and after tick.
    status = _status_of(statuses, last_s)
    assert status is not None and status.radio
    tick = round(status.sim_time_s * scenario.time.control_hz)
    low = {c.sender: (c.delivered, c.dropped) for c in counted[tick - 1]}
    high = {c.sender: (c.delivered, c.dropped) for c in counted[tick]}
    got = {c.sender: (c.delivered, c.dropped) for c in status.radio}
    assert set(got) == set(high) == {"uav2", "uav3", CLOCK}
    for sender, (delivered, dropped) in got.items():
        assert low[sender][0] <= delivered <= high[sender][0], (sender, got, low, high)
        assert low[sender][1] <= dropped <= high[sender][1], (sender, got, low, high)


def _keep_status(out: list[VehicleStatus], sample: zenoh.Sample) -> None:
    out.append(decode(sample.payload.to_bytes(), VehicleStatus))


def _status_of(statuses: list[VehicleStatus], since_s: float) -> VehicleStatus | None:
    """The newest status from ``since_s`` (sim time) on."""
    recent = [s for s in list(statuses) if s.sim_time_s >= since_s]
    return max(recent, key=lambda s: s.sim_time_s) if recent else None
