"""The fused runner against the distributed stack: the same state stream, bit for bit.

Both sides get the same scenario and the same commands at the same tick boundaries; on the
distributed side a clock holder in the test process (a parked scenario vehicle's participant,
:mod:`tests.clock_holder`) keeps the lockstep from moving on until the commands are answered.
Each side's digest covers every vehicle's state of every tick from 0.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from deploy.demo import StateDigest
from deploy.envs.clock import ClockHolder
from deploy.fused import FusedRunner
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    Command,
    FlightMode,
    MissionStart,
    PlumeQuery,
    SetMode,
    Takeoff,
    VehicleState,
)
from swarmbus.scenario import DEFAULT_SCENARIO, Scenario, load_scenario
from tests.procs import NodeProcs, wait_for_queryable, zenoh_network

CLOCK = "clock"
FLYERS = ("uav1", "uav2", "uav3")
CLOCK_VEHICLE = f"""
[[vehicles]]
id = "{CLOCK}"
spawn_enu_m = [-300.0, 0.0, 0.0]
"""
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
    scenario: Scenario, last_tick: int, boundary: Boundary
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
    assert all(maxima[v] > 5.0 for v in FLYERS), f"the flyers should have climbed: {maxima}"
    return digest.result(), runner


def distributed_stream(
    path: Path, scenario: Scenario, last_tick: int, boundary: Boundary, log_dir: Path
) -> dict:
    keys = Keys(scenario.world.name)
    with zenoh_network() as (net, session), NodeProcs(net, path, log_dir) as procs:
        procs.start("plume")
        wait_for_queryable(
            session,
            keys.plume_concentration(),
            encode(PlumeQuery(points_enu_m=[(30.0, 0.0, 10.0)], sim_time_s=0.0)),
            60.0,
            "the plume service",
        )
        for vid in FLYERS:
            procs.start("autopilot", "--vehicle", vid)
        holder = ClockHolder(session, keys, CLOCK, FLYERS, rotor_count=4)
        try:
            procs.start("physics")
            holder.run(last_tick, lambda k: boundary.get(k, []))
            return holder.digest.result()
        finally:
            holder.close()


def assert_same_stream(
    tmp_path: Path, path: Path, last_tick: int, boundary: Boundary
) -> FusedRunner:
    scenario = load_scenario(path)
    fused, runner = fused_stream(scenario, last_tick, boundary)
    distributed = distributed_stream(path, scenario, last_tick, boundary, tmp_path)
    runner.close()
    vehicles = len(scenario.vehicles)
    assert fused["messages"] == distributed["messages"] == (last_tick + 1) * vehicles
    assert distributed["missing"] == distributed["conflicts"] == 0
    assert fused["sha256"] == distributed["sha256"]
    return runner


def test_default_scenario_missions_give_the_same_states_fused_and_distributed(
    tmp_path: Path,
) -> None:
    boundary: Boundary = {0: [(v, c) for v in FLYERS for c in (Arm(), MissionStart())]}
    assert_same_stream(tmp_path, default_with_clock(tmp_path), 1200, boundary)


def test_casting_in_offboard_with_a_noisy_sensor_gives_the_same_states(tmp_path: Path) -> None:
    boundary: Boundary = {
        0: [(v, c) for v in FLYERS for c in (Arm(), Takeoff(altitude_m=10.0))],
        480: [(v, SetMode(mode=FlightMode.OFFBOARD)) for v in FLYERS],
    }
    runner = assert_same_stream(
        tmp_path, default_with_clock(tmp_path, noisy_casting=True), 1440, boundary
    )
    # Not a vacuous comparison: the behaviours flew on noisy readings of real gas.
    for vid in FLYERS:
        assert runner.flights[vid].autopilot.modes.mode == FlightMode.OFFBOARD, vid
    readings = [r for r in runner.latest_readings.values() if r.true_g_m3 is not None]
    assert readings and any(r.reported_g_m3 != r.true_g_m3 for r in readings)
