"""Acceptance of the autopilots with real processes: plume service + physics + autopilots,
lockstep, on loopback."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import zenoh

from agents import CommandRejected, Swarm
from plume_service import GaussianPlume
from swarmbus.messages import ConcentrationReading, FlightMode, VehicleState
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario
from swarmbus.session import Presence
from tests.support.procs import Network, NodeProcs, keys_for

HEADER = """
[world]
name = "default"
seed = 7

[time]
physics_hz = 240
control_hz = 120
mode = "lockstep"
participant_timeout_s = 5.0
startup_timeout_s = 120.0

[plume]
preset = "novak2018"

[sensor]
preset = "novak2018"
"""


def scenario_file(tmp_path: Path, vehicles: str, failsafe: str = "") -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(HEADER + (f"\n[failsafe]\n{failsafe}\n" if failsafe else "") + vehicles)
    load_scenario(path)  # fail here, not in a child, when the text is wrong
    return path


class Run:
    """Plume + autopilots + physics for a scenario, and a Swarm client on the same network."""

    def __init__(self, procs: NodeProcs, sw: Swarm, ids: list[str]) -> None:
        self.procs = procs
        self.sw = sw
        self.ids = ids

    def mode(self, vid: str) -> FlightMode | None:
        status = self.sw.status(vid)
        return status.mode if status is not None else None

    def wait_mode(self, vid: str, mode: FlightMode, timeout_s: float = 120.0) -> None:
        self.sw.wait_until(lambda: self.mode(vid) == mode, timeout_s, f"{vid} in mode {mode}")

    def alive(self) -> None:
        dead = [label for label, p in self.procs.procs if p.poll() is not None]
        assert not dead, f"processes died: {dead}"


@pytest.fixture
def run_factory(network: tuple[Network, zenoh.Session], tmp_path: Path) -> Iterator[object]:
    net, session = network
    stack: list[tuple[NodeProcs, Swarm]] = []

    def start(scenario: Path, ids: list[str]) -> Run:
        procs = NodeProcs(net, scenario, tmp_path)
        sw = Swarm.connect(connect=[net.endpoint], command_timeout_s=10.0)
        stack.append((procs, sw))
        procs.start("plume")
        for vid in ids:
            procs.start("autopilot", "--vehicle", vid)
        # as `plumeswarm up` does: the plume is serving before the lockstep starts, so every
        # reading, from the first sensor tick on, has an answer
        presence = Presence(session, keys_for())
        assert presence.wait_for(lambda alive: "plume" in alive, 60.0), sorted(presence.alive)
        presence.close()
        procs.start("physics")
        # Tick 1 is published only after every autopilot answered tick 0, i.e. after each
        # has its first state: a state of tick 0 alone may reach us before the autopilot.
        sw.wait_until(
            lambda: all(
                (state := sw.state(v)) is not None and state.tick >= 1 and sw.status(v) is not None
                for v in ids
            ),
            120.0,
            f"states (tick >= 1) and statuses of {ids}",
        )
        return Run(procs, sw, ids)

    yield start
    for procs, sw in stack:
        sw.close()
        procs.stop_all()


def test_novak2018_three_iris_hold_fly_the_mission_land_and_read_the_plume(
    run_factory: object,
) -> None:
    sc = load_scenario()
    ids = [v.id for v in sc.vehicles]
    run = run_factory(DEFAULT_SCENARIO, ids)  # type: ignore[operator]
    sw = run.sw
    states: dict[str, list[VehicleState]] = {v: [] for v in ids}
    readings: list[ConcentrationReading] = []
    sub = sw.subscribe(
        on_state=lambda s: states[s.vehicle_id].append(s), on_reading=readings.append
    )
    for vid in ids:
        sw.command(vid).arm()
        sw.command(vid).takeoff(10.0)
    for vid in ids:
        run.wait_mode(vid, FlightMode.HOLD)
    # settle 5 s of sim time, then every vehicle holds within 0.2 m for 10 s
    t0 = max(states[v][-1].sim_time_s for v in ids)
    sw.wait_until(
        lambda: min(states[v][-1].sim_time_s for v in ids) > t0 + 15.0, 120.0, "15 s of hover"
    )
    for vid in ids:
        home = sw.status(vid).home_enu_m
        hold = [s for s in states[vid] if t0 + 5.0 <= s.sim_time_s <= t0 + 15.0]
        assert len(hold) > 100
        target = (home[0], home[1], home[2] + 10.0)
        worst = max(math.dist(s.position_enu_m, target) for s in hold)
        assert worst <= 0.2, f"{vid} strayed {worst:.3f} m from its hover point"
    for vid in ids:
        sw.command(vid).start_mission()
    for vid in ids:
        sw.wait_until(
            lambda vid=vid: sw.status(vid).mission_finished and not sw.status(vid).armed,
            300.0,
            f"{vid} finished the mission, landed and disarmed",
        )
    sub.close()
    run.alive()
    for vid in ids:
        status = sw.status(vid)
        assert status is not None and status.landed and not status.crashed
        assert status.mission_items_reached == len(sc.vehicle(vid).mission)
    plume = GaussianPlume.preset("novak2018")
    assert readings and all(r.available for r in readings)
    truth = plume.concentration(np.array([r.position_enu_m for r in readings]))
    np.testing.assert_allclose(
        np.array([r.true_g_m3 for r in readings], float), truth, rtol=1e-9, atol=0
    )
    window = np.where(truth < 0.01, 0.0, np.minimum(truth, 0.2))
    np.testing.assert_allclose(
        np.array([r.reported_g_m3 for r in readings], float), window, rtol=1e-9, atol=0
    )
    inside = (window > 0.0) & (window < 0.2)
    assert inside.sum() > 100, "the mission should cross the sensor's window"


SQUARE = """
[[vehicles]]
id = "hexa"
type = "typhoon_h480"
spawn_enu_m = [20.0, 0.0, 0.0]
mission = [
  { command = "takeoff", x = 20.0, y = 0.0, z = 8.0 },
  { x = 30.0, y = 0.0, z = 8.0 },
  { x = 30.0, y = 10.0, z = 8.0 },
  { x = 20.0, y = 10.0, z = 8.0 },
  { x = 20.0, y = 0.0, z = 8.0 },
  { command = "land", x = 20.0, y = 0.0, z = 0.0 },
]
"""


def test_hexacopter_flies_a_square_mission_and_lands(run_factory: object, tmp_path: Path) -> None:
    run = run_factory(scenario_file(tmp_path, SQUARE), ["hexa"])  # type: ignore[operator]
    sw = run.sw
    corners: set[int] = set()
    square = [(30.0, 0.0, 8.0), (30.0, 10.0, 8.0), (20.0, 10.0, 8.0), (20.0, 0.0, 8.0)]

    def visit(s: VehicleState) -> None:
        for i, c in enumerate(square):
            if math.dist(s.position_enu_m, c) < 1.0:
                corners.add(i)

    sub = sw.subscribe(on_state=visit)
    sw.command("hexa").arm()
    sw.command("hexa").start_mission()
    sw.wait_until(
        lambda: sw.status("hexa").mission_finished and not sw.status("hexa").armed,
        300.0,
        "the hexacopter finished its square and disarmed",
    )
    sub.close()
    assert corners == {0, 1, 2, 3}
    state = sw.state("hexa")
    assert state is not None and state.on_ground and not state.crashed
    assert math.hypot(state.position_enu_m[0] - 20.0, state.position_enu_m[1]) < 0.5


ONE = """
[[vehicles]]
id = "uav1"
type = "iris"
spawn_enu_m = [20.0, 0.0, 0.0]
"""


def take_off(run: Run, vid: str, alt: float) -> None:
    run.sw.command(vid).arm()
    run.sw.command(vid).takeoff(alt)
    run.wait_mode(vid, FlightMode.HOLD)


def test_failsafe_datalink_loss_lands(run_factory: object, tmp_path: Path) -> None:
    path = scenario_file(tmp_path, ONE, 'datalink_loss_action = "land"\ndatalink_timeout_s = 2.0')
    run = run_factory(path, ["uav1"])  # type: ignore[operator]
    uav = run.sw.command("uav1")
    uav.heartbeat()
    uav.arm()
    uav.takeoff(5.0)
    # heartbeats stop here: 2 s of sim time later the link is declared lost
    run.sw.wait_until(
        lambda: run.sw.status("uav1").failsafe == "ground-control link lost",
        120.0,
        "the datalink failsafe",
    )
    run.sw.wait_until(
        lambda: run.mode("uav1") in (FlightMode.LAND, FlightMode.DISARMED), 30, "landing"
    )
    run.wait_mode("uav1", FlightMode.DISARMED)
    assert not run.sw.status("uav1").crashed


def test_failsafe_geofence_returns_home(run_factory: object, tmp_path: Path) -> None:
    path = scenario_file(tmp_path, ONE, "rtl_altitude_m = 6.0")
    run = run_factory(path, ["uav1"])  # type: ignore[operator]
    take_off(run, "uav1", 4.0)
    uav = run.sw.command("uav1")
    uav.goto(30.0, 0.0, 4.0)
    run.sw.wait_until(
        lambda: math.dist(run.sw.state("uav1").position_enu_m, (30.0, 0.0, 4.0)) < 0.5,
        120,
        "uav1 at 10 m from home",
    )
    uav.set_param("GF_MAX_HOR_DIST", 5.0)  # now it is outside the fence
    run.wait_mode("uav1", FlightMode.RTL, 30)
    assert run.sw.status("uav1").failsafe.startswith("geofence")
    run.wait_mode("uav1", FlightMode.DISARMED, 120)
    p = run.sw.state("uav1").position_enu_m
    assert math.hypot(p[0] - 20.0, p[1]) < 1.0


def test_failsafe_offboard_loss_and_crash(run_factory: object, tmp_path: Path) -> None:
    path = scenario_file(tmp_path, ONE, 'offboard_loss_action = "hold"')
    run = run_factory(path, ["uav1"])  # type: ignore[operator]
    take_off(run, "uav1", 8.0)
    uav = run.sw.command("uav1")
    uav.setpoint(position=(21.0, 0.0, 8.0))
    uav.offboard()
    # One setpoint: the stream times out and the vehicle holds. Wait for both together: the
    # status saying HOLD from before the offboard switch may still be the latest one here.
    run.sw.wait_until(
        lambda: (
            (st := run.sw.status("uav1")) is not None
            and st.mode == FlightMode.HOLD
            and st.failsafe == "offboard setpoint stream lost"
        ),
        30,
        "uav1 holding after the offboard stream was lost",
    )
    with pytest.raises(CommandRejected, match="force"):
        uav.disarm()
    uav.disarm(force=True)  # motors off at 8 m: it falls and crashes
    run.sw.wait_until(lambda: run.sw.status("uav1").crashed, 60, "the crash reported")
    status = run.sw.status("uav1")
    assert status is not None and not status.armed and status.failsafe == "crash"
    with pytest.raises(CommandRejected, match="crashed"):
        uav.arm()
    run.alive()


CASTER = """
[[vehicles]]
id = "moth"
type = "iris"
spawn_enu_m = [45.0, 6.0, 0.0]
behavior = "agents.behaviors.casting:Casting"
"""


def test_casting_behaviour_ends_closer_to_the_source(run_factory: object, tmp_path: Path) -> None:
    run = run_factory(scenario_file(tmp_path, CASTER), ["moth"])  # type: ignore[operator]
    sw = run.sw
    take_off(run, "moth", 10.0)
    start = sw.state("moth")
    assert start is not None
    sw.command("moth").offboard()
    sw.wait_until(
        lambda: sw.state("moth").sim_time_s > start.sim_time_s + 60.0, 300.0, "60 s of casting"
    )
    assert run.mode("moth") == FlightMode.OFFBOARD
    source = (0.0, 0.0, 10.0)
    before = math.dist(start.position_enu_m, source)
    after = math.dist(sw.state("moth").position_enu_m, source)
    assert after < 0.5 * before, (before, after)


def test_mox_sensor_readings_reach_the_swarm_client_with_ppm_and_resistance(
    run_factory: object, tmp_path: Path
) -> None:
    """A TGS2620 on a vehicle climbing into the plume: the Swarm client gets the gas, the ppm,
    the raw resistance on GADEN's curve, the rise lag on the way up and the settled value."""
    path = tmp_path / "mox.toml"
    path.write_text(
        HEADER.replace('[sensor]\npreset = "novak2018"', '[sensor]\npreset = "mox-tgs2620"') + ONE
    )
    load_scenario(path)
    run = run_factory(path, ["uav1"])  # type: ignore[operator]
    sw = run.sw
    readings: list[ConcentrationReading] = []
    sub = sw.subscribe(on_reading=readings.append)
    take_off(run, "uav1", 10.0)
    t_hold = sw.state("uav1").sim_time_s
    sw.wait_until(
        lambda: bool(readings) and readings[-1].sim_time_s > t_hold + 20.0, 120.0, "20 s of hover"
    )
    sub.close()
    run.alive()
    ethanol_g_mol = 2 * 12.011 + 6 * 1.008 + 15.999
    ppm_per_g_m3 = 8.314462618 * 298.15 / 101325.0 / ethanol_g_mol * 1e6
    for r in readings:
        assert r.available and r.gas == "ethanol"
        assert r.reported_g_m3 is not None and r.resistance_ohm is not None
        assert r.reported_ppm is not None and r.true_g_m3 is not None
        assert r.reported_ppm == pytest.approx(r.reported_g_m3 * ppm_per_g_m3, rel=1e-12)
        if r.reported_ppm > 0.0:  # RS/R0 on the published curve, read back by the calibration
            assert r.resistance_ohm / 3000.0 == pytest.approx(
                62.32 * r.reported_ppm**-0.7155, rel=1e-9
            )
        else:
            assert r.resistance_ohm == 21.0 * 3000.0  # clean air
    true = np.array([r.true_g_m3 for r in readings], float)
    reported = np.array([r.reported_g_m3 for r in readings], float)
    climbing = (np.array([r.sim_time_s for r in readings]) < t_hold) & (true > 0.01)
    assert np.any(reported[climbing] < 0.9 * true[climbing]), "no rise lag seen"
    last = readings[-1]
    assert last.reported_g_m3 == pytest.approx(last.true_g_m3, rel=0.03)
