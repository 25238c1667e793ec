"""What a vehicle's status changes mean in MAVLink, and the gateway's options, without I/O."""

from __future__ import annotations

import pytest

from gcs_bridge import mission as ms
from gcs_bridge.dialect import mavlink
from gcs_bridge.modes import decode_custom_mode
from gcs_bridge.options import GatewayOptions
from gcs_bridge.vehicle import ArmIntent, Vehicle
from swarmbus.messages import FlightMode, MissionItem
from swarmbus.options import OptionError, parse_options
from swarmbus.scenario import GatewaySpec, load_scenario
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
