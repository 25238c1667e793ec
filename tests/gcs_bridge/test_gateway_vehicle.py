"""What a vehicle's status changes mean in MAVLink, and the gateway's options, without I/O."""

from __future__ import annotations

import math

import pytest

from gcs_bridge import mission as ms
from gcs_bridge.dialect import mavlink
from gcs_bridge.modes import decode_custom_mode
from gcs_bridge.options import GatewayOptions
from gcs_bridge.telemetry import vfr_hud
from gcs_bridge.vehicle import ArmIntent, Vehicle
from plume_atmosphere.wind import wind_from_scenario
from swarmbus.messages import FlightMode, MissionItem
from swarmbus.options import OptionError, parse_options
from swarmbus.scenario import GatewaySpec, load_scenario, parse_scenario
from tests.support.messages_samples import vehicle_state
from tests.support.messages_samples import vehicle_status as status

SCENARIO = load_scenario()


def vehicle() -> Vehicle:
    return Vehicle(SCENARIO, "uav1", 0, (6.0, 0.0, 0.0))


def test_items_reached_become_mavlink_seqs_once_each() -> None:
    v = vehicle()
    items = [MissionItem(x=0, y=0, z=5), MissionItem(x=5, y=0, z=5), MissionItem(x=5, y=5, z=5)]
    v.remember_upload(ms.Converted(items=items, seqs=[0, 2, 3], wire=[]))
    first = v.update_status(status(mission_count=3, mission_index=0), 0.0)
    assert first.heartbeat and first.reached_seqs == []
    ev = v.update_status(status(mission_count=3, mission_index=2, mission_items_reached=2), 0.1)
    assert ev.reached_seqs == [0, 2] and ev.mission_current
    assert v.update_status(status(mission_count=3, mission_items_reached=2), 0.2).reached_seqs == []
    ev = v.update_status(
        status(mission_count=3, mission_items_reached=3, mission_finished=True), 0.3
    )
    assert ev.reached_seqs == [3]
    assert v.mission_current().state == mavlink.MISSION_STATE_COMPLETE


def test_first_status_mid_mission_announces_nothing_old() -> None:
    v = vehicle()
    ev = v.update_status(status(mission_count=7, mission_items_reached=4, mission_index=4), 0.0)
    assert ev.reached_seqs == []


def test_disarmed_heartbeat_shows_the_selected_mode_until_armed() -> None:
    v = vehicle()
    v.update_status(status(), 0.0)
    v.intent = ArmIntent(FlightMode.TAKEOFF, 5.0)
    mode = decode_custom_mode(v.heartbeat().custom_mode)
    assert (mode.main, mode.sub) == (4, 2)
    v.update_status(status(mode=FlightMode.ARMED, armed=True), 0.1)
    assert v.intent is None
    mode = decode_custom_mode(v.heartbeat().custom_mode)
    assert (mode.main, mode.sub) == (4, 3)


def test_armable_says_why_not() -> None:
    v = vehicle()
    assert v.armable() is not None  # no status yet
    v.update_status(status(), 0.0)
    assert v.armable() is None
    v.update_status(status(health="plume service silent"), 0.1)
    assert "plume" in (v.armable() or "")


def test_options_are_checked_and_rates_configurable() -> None:
    given = {"rate.ATTITUDE": "10", "signed_links": "gcs", "api_links": "off"}
    o = parse_options(GatewayOptions, given)
    assert o.rates_hz()[mavlink.MAVLINK_MSG_ID_ATTITUDE] == 10.0
    assert o.signs("gcs") and not o.signs("api") and not o.api_links
    for kind in ("gcs", "api"):
        assert o.bind_host_for(GatewaySpec(), kind) == "127.0.0.1"
        assert GatewayOptions().bind_host_for(GatewaySpec(host="192.0.2.7"), kind) == "0.0.0.0"
    # a remote ground station, the API clients on this machine: only the GCS link is exposed
    remote_gcs = GatewaySpec(host="192.0.2.7", api_host="127.0.0.1")
    assert GatewayOptions().bind_host_for(remote_gcs, "gcs") == "0.0.0.0"
    assert GatewayOptions().bind_host_for(remote_gcs, "api") == "127.0.0.1"
    pinned = parse_options(GatewayOptions, {"bind_host": "10.0.0.2", "api_bind_host": "127.0.0.3"})
    assert pinned.bind_host_for(GatewaySpec(), "gcs") == "10.0.0.2"
    assert pinned.bind_host_for(GatewaySpec(), "api") == "127.0.0.3"
    for bad in (
        {"nope": "1"},
        {"rate.NOT_A_MESSAGE": "1"},
        {"rate.HEARTBEAT": "5"},
        {"gcs_bind_port": "70000"},
        {"cmd_timeout_s": "nan"},
        {"api_links": "maybe"},
    ):
        with pytest.raises(OptionError):
            parse_options(GatewayOptions, bad).rates_hz()


def test_a_planes_airspeed_is_against_the_physics_wind_a_quads_against_the_steady() -> None:
    """VFR_HUD airspeed of a plane in a meandering, turbulent wind: its velocity minus the
    wind the physics builds from the scenario, where and when it flies."""
    sc = parse_scenario(
        '[wind]\nspeed_m_s = 3.0\nfrom_deg = 270.0\nmodel = "meander"\n'
        '[wind.meander]\npreset = "small"\n'
        "[wind.turbulence]\nstd_m_s = [1.0, 1.0, 0.5]\nlength_scale_m = 20.0\ntimescale_s = 2.0\n"
        '[[vehicles]]\nid = "p"\ntype = "aerosonde"\nsysid = 1\n'
        '[[vehicles]]\nid = "q"\ntype = "iris"\nsysid = 2\n'
    )
    steady = (3.0, 0.0, 0.0)
    plane = Vehicle(sc, "p", 0, steady, wind_from_scenario(sc))
    quad = Vehicle(sc, "q", 1, steady, wind_from_scenario(sc))
    physics_wind = wind_from_scenario(sc)  # what sim_world.world builds from the scenario
    velocity = (25.0, 4.0, 1.0)
    gusts = []
    for t in (5.0, 20.0, 40.0, 60.0, 90.0):
        where = (25.0 * t, 4.0 * t, 40.0)
        for v in (plane, quad):
            v.state = vehicle_state(
                v.id, position_enu_m=where, velocity_enu_m_s=velocity, sim_time_s=t
            )
        w = physics_wind.velocity([where], t)[0]
        expected = math.dist(velocity, (float(w[0]), float(w[1]), float(w[2])))
        hud = vfr_hud(plane.view(), plane.state)  # type: ignore[arg-type]
        assert hud.airspeed == pytest.approx(expected, abs=1e-5)  # a float32 on the wire
        assert hud.groundspeed == pytest.approx(math.hypot(25.0, 4.0), abs=1e-5)
        assert hud.climb == pytest.approx(1.0)
        quad_hud = vfr_hud(quad.view(), quad.state)  # type: ignore[arg-type]
        assert quad_hud.airspeed == pytest.approx(math.dist(velocity, steady), abs=1e-5)
        gusts.append(abs(expected - math.dist(velocity, steady)))
    assert max(gusts) > 0.1  # meander and gusts: the plane's airspeed is not the steady one
    assert plane.mav_type == mavlink.MAV_TYPE_FIXED_WING
    assert quad.mav_type == mavlink.MAV_TYPE_QUADROTOR
