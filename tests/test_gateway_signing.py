"""MAVLink 2 signing per link: a signed client commands a vehicle, unsigned and wrongly signed
traffic is refused; with ``signed_links=gcs`` the API ports stay open to unsigned clients
(MAVSDK's Python binding cannot sign)."""

from __future__ import annotations

import os
from pathlib import Path

from gcs_bridge.dialect import mavlink
from tests.gateway_stack import gateway, vehicles
from tests.mavclient import MavClient, write_scenario
from tests.procs import zenoh_network

KEY = os.urandom(32)


def standby(c: MavClient, sysid: int) -> None:
    c.wait(
        "standby",
        lambda m: (
            m.get_type() == "HEARTBEAT"
            and m.get_srcSystem() == sysid
            and m.system_status == mavlink.MAV_STATE_STANDBY
        ),
        120.0,
    )


def test_signed_gcs_link_refuses_unsigned_and_wrong_keys(tmp_path: Path) -> None:
    scenario, gcs_port, api_base = write_scenario(
        tmp_path / "scenario.toml", 1, signing_key_hex=KEY.hex()
    )
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1"], speed=2.0),
        gateway(net, scenario, tmp_path, "signed_links=gcs", "cmd_timeout_s=3"),
        MavClient(gcs_port, signing_key=KEY) as signed,
        MavClient(0) as unsigned,
        MavClient(0, system=254, signing_key=os.urandom(32)) as forger,
        MavClient(api_base) as api_client,
    ):
        standby(signed, 1)
        hb = signed.wait_type("HEARTBEAT", 1)
        assert hb.get_msgbuf()[2] & mavlink.MAVLINK_IFLAG_SIGNED  # the gateway signs too
        gateway_addr = signed.addr_of[1]
        for intruder in (unsigned, forger):
            intruder.addr_of[1] = gateway_addr  # they talk to the same GCS socket
            intruder.send(
                1, mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
            )
        # the signed client's next command is handled after those (one socket, FIFO)
        assert signed.command(1, mavlink.MAV_CMD_REQUEST_MESSAGE, 0) == mavlink.MAV_RESULT_ACCEPTED
        signed.drain()
        hb = signed.wait_type("HEARTBEAT", 1)
        assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED, "an unsigned ARM got in"
        for intruder in (unsigned, forger):
            intruder.pump(0.2)
            assert not [m for m in intruder.log if m.get_type() == "COMMAND_ACK"]
        assert signed.command(1, 400, 1) == mavlink.MAV_RESULT_ACCEPTED
        signed.wait(
            "armed",
            lambda m: (
                m.get_type() == "HEARTBEAT"
                and m.get_srcSystem() == 1
                and m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            ),
        )
        # the API link is unsigned here: an unsigned client is served there
        standby_or_armed = api_client.wait_type("HEARTBEAT", 1)
        assert not standby_or_armed.get_msgbuf()[2] & mavlink.MAVLINK_IFLAG_SIGNED
        assert api_client.command(1, 400, 0) == mavlink.MAV_RESULT_ACCEPTED  # disarm on ground
