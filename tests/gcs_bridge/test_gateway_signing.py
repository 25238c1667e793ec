"""MAVLink 2 signing per link: a signed client commands a vehicle, unsigned and wrongly signed
traffic is refused; with ``signed_links=gcs`` the API ports stay open to unsigned clients
(MAVSDK's Python binding cannot sign)."""

from __future__ import annotations

import hashlib
import math
import os
import re
import socket
import time
from pathlib import Path
from typing import Any

import pytest
from pymavlink import mavutil

from gcs_bridge.dialect import Msg, mavlink, new_mav, pack
from gcs_bridge.frames import enu_to_geodetic
from gcs_bridge.links import signing_timestamp_now
from gcs_bridge.options import signing_key
from swarmbus.messages import FlightMode, VehicleStatus
from swarmbus.options import OptionError
from swarmbus.scenario import GatewaySpec, load_scenario
from tests.gcs_bridge.test_gateway_mavproxy import MAVPROXY, mavproxy_console
from tests.support.buswatch import BusWatch
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import GCS_COMPID, GCS_SYSID, MavClient, mission_item, write_scenario
from tests.support.mavfuzz import Fuzzer, Target
from tests.support.procs import wait_until, zenoh_network

KEY = os.urandom(32)
NAN = math.nan
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def test_signed_gcs_link_refuses_unsigned_and_wrong_keys(tmp_path: Path) -> None:
    scenario, gcs_port, api_base = write_scenario(
        tmp_path / "scenario.toml", 1, signing_key_hex=KEY.hex()
    )
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1"], backend="real"),
        gateway(net, scenario, tmp_path, "signed_links=gcs", "cmd_timeout_s=3"),
        MavClient(gcs_port, signing_key=KEY) as signed,
        MavClient(0) as unsigned,
        MavClient(0, system=254, signing_key=os.urandom(32)) as forger,
        MavClient(api_base) as api_client,
    ):
        signed.wait_standby(1)
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
        signed.wait_armed(1)
        # the API link is unsigned here: an unsigned client is served there
        standby_or_armed = api_client.wait_type("HEARTBEAT", 1)
        assert not standby_or_armed.get_msgbuf()[2] & mavlink.MAVLINK_IFLAG_SIGNED
        assert api_client.command(1, 400, 0) == mavlink.MAV_RESULT_ACCEPTED  # disarm on ground


# ----------------------------------------------------------------------------- the key file
def gateway_section(**kw: str) -> GatewaySpec:
    return GatewaySpec(**kw)  # type: ignore[arg-type]


def test_the_key_file_is_read_only_when_private_to_its_owner(tmp_path: Path) -> None:
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(KEY.hex() + "\n")
    key_file.chmod(0o600)
    assert signing_key(gateway_section(signing_key_file=str(key_file))) == KEY
    for mode in (0o640, 0o604, 0o660, 0o644):
        key_file.chmod(mode)
        with pytest.raises(OptionError, match=re.escape(f"chmod 600 {key_file}")):
            signing_key(gateway_section(signing_key_file=str(key_file)))
    key_file.chmod(0o600)
    with pytest.raises(OptionError, match="not both"):
        signing_key(gateway_section(signing_key_file=str(key_file), signing_key_hex=KEY.hex()))
    bad = tmp_path / "bad.key"
    for content in (b"", b"abc", KEY, (KEY.hex() + "00").encode(), b"\xff" * 64):
        bad.write_bytes(content)
        bad.chmod(0o600)
        with pytest.raises(OptionError, match=r"64 hex digits|cannot read"):
            signing_key(gateway_section(signing_key_file=str(bad)))
    with pytest.raises(OptionError, match="no such file"):
        signing_key(gateway_section(signing_key_file=str(tmp_path / "missing.key")))
    with pytest.raises(OptionError, match="not a regular file"):
        signing_key(gateway_section(signing_key_file=str(tmp_path)))
    assert signing_key(gateway_section()) is None


# ----------------------------------------------------------------------------- real autopilot
class SignedGcs:
    """pymavlink's own client (``mavutil`` udpin + ``setup_signing``), speaking MAVLink 2 through
    a dialect object we construct; every frame it sends is kept (the attacker replays them)."""

    def __init__(self, port: int, key: bytes) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=GCS_SYSID, source_component=GCS_COMPID
        )
        self.conn.mav = mavlink.MAVLink(self.conn, srcSystem=GCS_SYSID, srcComponent=GCS_COMPID)
        # mavutil would swap in a new (unsigned) encoder at the first MAVLink 2 byte it hears,
        # and set MAVLINK20 in os.environ on the way: we already speak MAVLink 2
        self.conn.first_byte = False
        self.conn.WIRE_PROTOCOL_VERSION = "2.0"
        self.conn.setup_signing(key, sign_outgoing=True)
        self.sent: list[bytes] = []
        write = self.conn.write

        def keep(buf: bytes) -> None:
            self.sent.append(bytes(buf))
            write(buf)

        self.conn.write = keep

    def close(self) -> None:
        self.conn.close()

    def recv(self, kind: str | list[str], timeout_s: float = 30.0, **fields: object) -> Msg:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            m = self.conn.recv_match(type=kind, blocking=True, timeout=min(left, 0.5))
            if m is None or m.get_srcSystem() != 1:
                continue
            if all(getattr(m, k) == v for k, v in fields.items()):
                return m
        raise AssertionError(f"no {kind} {fields} within {timeout_s} s")

    def command(self, command: int, *params: float) -> int:
        p = [*params, *([0.0] * (7 - len(params)))]
        self.conn.mav.command_long_send(1, 1, command, 0, *p)
        return int(self.recv("COMMAND_ACK", command=command).result)

    def upload(self, items: list[Msg]) -> int:
        self.conn.mav.mission_count_send(1, 1, len(items), 0)
        while True:
            m = self.recv(["MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ACK"])
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            self.conn.mav.send(items[m.seq])

    def param(self, name: str) -> float:
        self.conn.mav.param_request_read_send(1, 1, name.encode(), -1)
        return float(self.recv("PARAM_VALUE", param_id=name).param_value)


def attacks(lat: float, lon: float) -> list[Msg]:
    """Everything that would change the vehicle: arm, takeoff, modes, mission upload / clear,
    parameters, go-to."""
    items = [
        mission_item(1, 0, mavlink.MAV_CMD_NAV_TAKEOFF, lat, lon, 5),
        mission_item(1, 1, mavlink.MAV_CMD_NAV_WAYPOINT, lat + 1e-4, lon, 5),
    ]
    return [
        mavlink.MAVLink_command_long_message(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_command_int_message(1, 1, 0, 400, 0, 0, 1, 0, 0, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, 22, 0, 0, 0, 0, NAN, 0, 0, 10),
        mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 4, 4, 0, 0, 0, 0),
        mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 4, 3, 0, 0, 0, 0),
        mavlink.MAVLink_set_mode_message(1, 1, 4 << 16 | 4 << 24),
        mavlink.MAVLink_command_int_message(
            1, 1, 6, 192, 0, 0, -1, 1, 0, NAN, round(lat * 1e7), round(lon * 1e7), 30
        ),
        mavlink.MAVLink_mission_count_message(1, 1, len(items), 0),
        *items,
        mavlink.MAVLink_mission_clear_all_message(1, 1, 0),
        mavlink.MAVLink_param_set_message(1, 1, b"MIS_TAKEOFF_ALT", 33.0, 9),
        mavlink.MAVLink_command_long_message(1, 1, 300, 0, 0, 0, 0, 0, 0, 0, 0),
    ]


def forged(msg: Msg, key: bytes, link_id: int, timestamp: int) -> bytes:
    """``msg`` signed with ``key`` at ``timestamp`` (10 µs units since 2015)."""
    mav = new_mav(GCS_SYSID, GCS_COMPID)
    mav.signing.secret_key = key
    mav.signing.link_id = link_id
    mav.signing.timestamp = timestamp
    mav.signing.sign_outgoing = True
    return bytes(pack(mav, msg))


def unsigned_wrong_and_stale(lat: float, lon: float, unsigned: Any, wrong: bytes) -> list[bytes]:
    """Every attack frame unsigned (MAVLink 2, and 1 where it fits), with a wrong key, and
    signed with the right key but 10 min stale."""
    stamp = signing_timestamp_now()
    frames: list[bytes] = []
    for msg in attacks(lat, lon):
        frames.append(bytes(pack(unsigned, msg)))
        if msg.id < 256:
            frames.append(bytes(msg.pack(unsigned, force_mavlink1=True)))
        frames.append(forged(msg, wrong, 0, stamp))
        frames.append(forged(msg, KEY, 7, stamp - 10 * 60 * 100_000))  # 10 min old
    return frames


def assert_unchanged(statuses: list[VehicleStatus], before: VehicleStatus) -> None:
    for st in statuses:
        assert (st.armed, st.mode, st.mission_count) == (
            before.armed,
            before.mode,
            before.mission_count,
        ), f"a refused frame changed the vehicle: {st}"


def test_unsigned_forged_and_replayed_frames_change_nothing_signed_ones_fly(
    tmp_path: Path,
) -> None:
    """Real autopilot, every link signed: arm, takeoff, mode changes, mission uploads and the
    rest, unsigned (MAVLink 2 and 1), with a wrong key, replayed, or stale, have no effect on
    the bus; the signed pymavlink client's do. Attackers hear nothing back."""
    key_file = tmp_path / "mavlink.key"  # the documented way: a private key file
    key_file.write_text(KEY.hex() + "\n")
    key_file.chmod(0o600)
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", 1, signing_key_file=key_file)
    sc = load_scenario(scenario)
    lat, lon, _ = enu_to_geodetic(sc.vehicles[0].spawn_enu_m, sc.world.origin)
    attackers = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    for s in attackers:
        s.bind(("127.0.0.1", 0))
        s.setblocking(False)
    with (
        zenoh_network() as (net, router),
        vehicles(net, scenario, tmp_path, ["uav1"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3") as gw,
    ):
        gcs = SignedGcs(gcs_port, KEY)
        watch = BusWatch(router, ["uav1"])
        try:
            gcs.recv("HEARTBEAT", 120.0, system_status=mavlink.MAV_STATE_STANDBY)
            wait_until(
                lambda: (s := watch.latest_status("uav1")) is not None and s.sim_time_s > 0.5,
                60.0,
                "the simulation running",
            )
            (gw_addr,) = gcs.conn.clients  # where the gateway's GCS link speaks from
            takeoff_alt = gcs.param("MIS_TAKEOFF_ALT")

            statuses: list[VehicleStatus] = []  # every status seen during attacks

            def attack(frames: list[bytes]) -> None:
                """Send ``frames`` from strangers, then prove they did nothing: a signed
                PARAM_SET goes through the same per-vehicle command queue behind anything
                they could have started, and a status newer than its answer shows the bus."""
                watch.mark()
                for i, frame in enumerate(frames):
                    attackers[i % 2].sendto(frame, gw_addr)
                gcs.conn.mav.param_set_send(1, 1, b"MIS_TAKEOFF_ALT", takeoff_alt, 9)
                answers = ["PARAM_VALUE", "COMMAND_ACK", "MISSION_ACK", "MISSION_REQUEST_INT"]
                while True:
                    m = gcs.recv(answers)
                    assert m.get_type() == "PARAM_VALUE", f"an attacker got an answer: {m}"
                    assert m.param_value == takeoff_alt, f"an attacker set a parameter: {m}"
                    if m.param_id == "MIS_TAKEOFF_ALT":
                        break
                seen = len(watch.status_window("uav1"))
                wait_until(lambda: len(watch.status_window("uav1")) > seen, 30.0, "a newer status")
                statuses.extend(watch.status_window("uav1"))

            # 1. on the ground, disarmed: unsigned (MAVLink 2 and 1), wrong key, stale
            wrong = os.urandom(32)
            unsigned = new_mav(GCS_SYSID, GCS_COMPID)
            frames = unsigned_wrong_and_stale(lat, lon, unsigned, wrong)
            # and the fuzzer's unsigned traffic (each of its client frames would be answered)
            fuzz = [d.data for d in Fuzzer(1, [Target(1, False, lat, lon)]).datagrams(5000)]
            before = watch.latest_status("uav1")
            for chunk in range(0, len(fuzz), 40):  # bursts the gateway's socket buffer holds
                attack(fuzz[chunk : chunk + 40])
            attack(frames)
            assert before is not None and not before.armed
            assert_unchanged(statuses, before)
            assert gcs.param("MIS_TAKEOFF_ALT") == takeoff_alt

            # 2. the signed client: upload, takeoff + arm, DO_SET_MODE hold, SET_MODE mission
            items = [
                mission_item(1, 0, mavlink.MAV_CMD_NAV_TAKEOFF, lat, lon, 6),
                mission_item(1, 1, mavlink.MAV_CMD_NAV_WAYPOINT, lat + 4e-5, lon, 6),
                mission_item(1, 2, mavlink.MAV_CMD_NAV_WAYPOINT, lat + 4e-5, lon + 4e-5, 6),
            ]
            assert gcs.upload(items) == mavlink.MAV_MISSION_ACCEPTED
            wait_until(
                lambda: (s := watch.latest_status("uav1")) is not None and s.mission_count == 3,
                30.0,
                "the signed upload on the bus",
            )
            assert gcs.command(22, 0, 0, 0, NAN, 0, 0, 8) == ACCEPTED
            arm_frame = len(gcs.sent)
            assert gcs.command(400, 1) == ACCEPTED
            arm = gcs.sent[arm_frame]
            wait_until(
                lambda: (
                    (s := watch.latest_status("uav1")) is not None and s.mode == FlightMode.HOLD
                ),
                120.0,
                "uav1 holding after its signed takeoff",
            )
            gcs.conn.mav.set_mode_send(1, 1, 4 << 16 | 4 << 24)  # SET_MODE: AUTO / MISSION
            wait_until(
                lambda: (
                    (s := watch.latest_status("uav1")) is not None and s.mode == FlightMode.MISSION
                ),
                30.0,
                "the signed SET_MODE on the bus",
            )
            assert gcs.command(176, 1, 4, 3) == ACCEPTED  # DO_SET_MODE: AUTO / LOITER (hold)
            wait_until(
                lambda: (
                    (s := watch.latest_status("uav1")) is not None and s.mode == FlightMode.HOLD
                ),
                30.0,
                "the signed DO_SET_MODE on the bus",
            )

            # 3. in the air: replays of the signed client's own frames (the ARM, the SET_MODE
            # to MISSION, the whole upload) and the attacks again
            frames = [arm, *gcs.sent] + [bytes(pack(unsigned, m)) for m in attacks(lat, lon)]
            frames += [forged(m, wrong, 0, signing_timestamp_now()) for m in attacks(lat, lon)]
            statuses.clear()
            attack(frames)
            for st in statuses:
                assert st.mode == FlightMode.HOLD and st.armed and st.mission_count == 3, (
                    f"a refused frame changed the vehicle in the air: {st}"
                )
            for s in attackers:
                with pytest.raises(BlockingIOError):
                    s.recv(65535)  # the gateway never answered (nor streamed to) a stranger
            assert gw.poll() is None
        finally:
            watch.close()
            gcs.close()
            for s in attackers:
                s.close()


# ----------------------------------------------------------------------------- MAVProxy
@pytest.mark.skipif(not Path(MAVPROXY).exists(), reason="mavproxy not installed")
def test_mavproxy_is_ignored_until_it_has_the_passphrase(tmp_path: Path) -> None:
    """MAVProxy's ``signing key PASSPHRASE`` (SHA-256 of the passphrase, as QGC does) on a
    vehicle's API link: its unsigned ARM before the key does nothing, its signed takeoff and
    ARM after it are accepted, in that order."""
    passphrase = "plume-test-passphrase"
    key_file = tmp_path / "mavlink.key"
    key_file.write_text(hashlib.sha256(passphrase.encode()).hexdigest() + "\n")
    key_file.chmod(0o600)
    scenario, gcs_port, api_base = write_scenario(
        tmp_path / "scenario.toml", 1, signing_key_file=key_file
    )
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
        MavClient(gcs_port) as watch,  # listens only: no key needed to read signed telemetry
    ):
        watch.wait_standby(1)
        console = mavproxy_console(api_base, 1, tmp_path)
        try:
            console.expect("Detected vehicle 1:1")  # it reads the gateway's signed heartbeats
            console.type("arm throttle")  # unsigned: dropped by the gateway
            console.type(f"signing key {passphrase}")
            console.expect("Setup signing key")
            console.type("takeoff 7")
            console.expect("NAV_TAKEOFF: ACCEPTED")
            console.type("arm throttle")
            console.expect("COMPONENT_ARM_DISARM: ACCEPTED")
            watch.wait_armed(1)
            acks = [
                line
                for line in console.lines
                if "NAV_TAKEOFF:" in line
                or "COMPONENT_ARM_DISARM:" in line
                or line.endswith("> ARMED")
                or line == "ARMED"
            ]
            assert "NAV_TAKEOFF" in acks[0], f"something answered the unsigned ARM: {acks}"
            assert sum("COMPONENT_ARM_DISARM" in line for line in acks) == 1, acks
        finally:
            console.close()
