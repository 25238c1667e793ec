"""Signed frames replayed where they were not sent: on another link, or after the gateway was
killed (``SIGKILL``) and restarted on the same signing-state file (MAVLink signing: a stream's
timestamp only goes up, and is kept across restarts). Links in-process first, then a real
gateway with fake autopilots."""

from __future__ import annotations

import os
import select
import signal
import socket
import time
from pathlib import Path

from gcs_bridge.dialect import mavlink, new_mav, pack
from gcs_bridge.links import Link, Signing, signing_timestamp_now
from tests.support.gateway_stack import node, stop, vehicles
from tests.support.mavclient import MavClient, write_scenario
from tests.support.procs import zenoh_network

KEY = os.urandom(32)
ARM = 400
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def signed_mav(system: int = 255) -> object:
    mav = new_mav(system, 190)
    mav.signing.secret_key = KEY
    mav.signing.link_id = 3
    mav.signing.timestamp = signing_timestamp_now()
    mav.signing.sign_outgoing = True
    return mav


def delivered(sock: socket.socket, link: Link, data: bytes) -> list[str]:
    before = link.stats.datagrams
    sock.sendto(data, link.address)
    deadline = time.monotonic() + 5.0
    got: list[str] = []
    while link.stats.datagrams == before:
        assert time.monotonic() < deadline, "the datagram never arrived"
        select.select([link.sock], [], [], 0.05)
        got += [m.get_type() for m, _ in link.receive(time.monotonic())]
    return got


def test_a_frame_taken_on_one_link_is_a_replay_on_another_and_after_a_restart(
    tmp_path: Path,
) -> None:
    state = tmp_path / "signing.state"
    frame = pack(signed_mav(), mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    shared = Signing(KEY, state)
    gcs = Link("gcs", ("127.0.0.1", 0), None, [1], shared)
    api = Link("api-uav1", ("127.0.0.1", 0), None, [1], shared, link_id=1)
    try:
        assert delivered(sock, gcs, frame) == ["HEARTBEAT"]
        assert delivered(sock, api, frame) == []  # the same stream, whichever socket
        assert api.stats.refused_bad_signature == 1
    finally:
        gcs.close()
        api.close()
        shared.close()
    # without the file (the state before): a restarted gateway would take it again
    again = Link("gcs", ("127.0.0.1", 0), None, [1], Signing(KEY))
    restarted = Link("gcs", ("127.0.0.1", 0), None, [1], Signing(KEY, state))
    try:
        assert delivered(sock, again, frame) == ["HEARTBEAT"]
        assert delivered(sock, restarted, frame) == []
        fresh = pack(signed_mav(), mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3))
        assert delivered(sock, restarted, fresh) == ["HEARTBEAT"]
    finally:
        for link in (again, restarted):
            link.close()
            assert link.signing is not None
            link.signing.close()
        sock.close()


def arm_answered_before_a_fence(client: MavClient) -> bool:
    """Whether an ARM_DISARM was answered before the answer to a LAND sent after it: both
    go to the autopilot, in order, on the same socket (a refused frame gets no answer)."""
    client.command(1, mavlink.MAV_CMD_NAV_LAND)  # on the ground, disarmed: whatever it says
    return any(m.get_type() == "COMMAND_ACK" and m.command == ARM for m in client.log)


def test_a_captured_arm_replayed_on_another_link_or_after_a_sigkill_arms_nothing(
    tmp_path: Path,
) -> None:
    scenario, gcs_port, api_base = write_scenario(
        tmp_path / "scenario.toml", 1, signing_key_hex=KEY.hex()
    )
    state = tmp_path / "mavlink-signing.state"
    sets = ["--set", f"signing_state={state}", "--set", "cmd_timeout_s=3"]
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1"]),
        MavClient(gcs_port, signing_key=KEY) as gcs,
        MavClient(api_base, signing_key=KEY) as api,
    ):
        api.mav.signing.link_id = 2  # a stream of its own (the GCS client's link id is 1)
        first = node(net, "gateway", scenario, tmp_path / "gateway-1.log", *sets)
        try:
            gcs.wait_standby(1)
            api.wait_type("HEARTBEAT", 1)
            captured = pack(
                gcs.mav, mavlink.MAVLink_command_long_message(1, 1, ARM, 0, 1, 0, 0, 0, 0, 0, 0)
            )
            gcs.send_raw(1, captured)
            assert gcs.wait_type("COMMAND_ACK", 1, 30.0, command=ARM).result == ACCEPTED
            gcs.wait_armed(1)
            assert gcs.command(1, ARM, 0) == ACCEPTED  # disarm (on the ground)
            gcs.wait_armed(1, armed=False)
            api.drain()
            api.log.clear()
            api.send_raw(1, captured)  # the capture, on the vehicle's API link
            assert not arm_answered_before_a_fence(api)
        finally:
            os.killpg(first.pid, signal.SIGKILL)
            first.wait(10)
        second = node(net, "gateway", scenario, tmp_path / "gateway-2.log", *sets)
        try:
            gcs.drain()
            gcs.wait_type("HEARTBEAT", 1)
            gcs.log.clear()
            gcs.send_raw(1, captured)  # the capture again, after the restart
            assert not arm_answered_before_a_fence(gcs)
            hb = gcs.wait_type("HEARTBEAT", 1)
            assert not hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
            assert gcs.command(1, ARM, 1) == ACCEPTED  # a fresh signed arm still flies
        finally:
            stop(second)
