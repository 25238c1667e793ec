"""The gateway as a real process between a raw MAVLink ground station and the bus.

uav1 and uav2 are flown by a scripted fake autopilot process
(tests/support/fake_autopilot.py: the bus contract with kinematic motion); uav3 is played by
this test itself on the same fake autopilot's bus side (``FakeAutopilot``), so that it can see
exactly which bus commands the gateway sends and choose the replies. The client replays what
QGroundControl does (connect sequence, takeoff, SET_MODE, missions) and hostile frames.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import zenoh

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import enu_to_geodetic
from gcs_bridge.params import float_bits_of_int
from swarmbus.keys import Keys
from swarmbus.messages import (
    Command,
    CommandReply,
    FlightMode,
    GcsHeartbeat,
    GetParams,
    MissionUpload,
    RejectCode,
    SetParam,
    VehicleStatus,
)
from swarmbus.scenario import Origin
from swarmbus.session import open_session
from tests.support.fake_autopilot import FakeAutopilot
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import (
    FAST_STREAMS,
    SLOW_STREAMS_HZ,
    MavClient,
    mission_item,
    write_scenario,
)
from tests.support.procs import Network, wait_until, zenoh_network

ORIGIN = Origin()
NAN = math.nan
UAV3 = 3
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
TEMP_REJECTED = mavlink.MAV_RESULT_TEMPORARILY_REJECTED
DENIED = mavlink.MAV_RESULT_DENIED
UNSUPPORTED = mavlink.MAV_RESULT_UNSUPPORTED
FAILED = mavlink.MAV_RESULT_FAILED


def _accept_after(delay_s: float) -> Callable[[Any], CommandReply]:
    """A reply script: accept, after ``delay_s`` of wall time."""

    def reply(cmd: Any) -> CommandReply:
        time.sleep(delay_s)
        return CommandReply(vehicle_id="uav3", accepted=True)

    return reply


def _refuse_with(code: RejectCode) -> Callable[[Any], CommandReply]:
    def reply(cmd: Any) -> CommandReply:
        return CommandReply(vehicle_id="uav3", accepted=False, code=code, reason="scripted")

    return reply


@dataclass
class ScriptedVehicle:
    """uav3: the fake autopilot's bus side for one vehicle, answering from ``replies`` (accept
    when no script; a script's None is no reply), and the statuses this test publishes."""

    session: zenoh.Session
    keys: Keys
    vid: str = "uav3"
    received: list[Any] = field(default_factory=list)
    replies: dict[type, Callable[[Any], CommandReply | None]] = field(default_factory=dict)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def start(self) -> None:
        self._autopilot = FakeAutopilot(self.session, self.keys, self.vid)
        self._autopilot.serve(self._on_command)

    def publish_status(self, **kw: Any) -> None:
        base: dict[str, Any] = dict(
            vehicle_id=self.vid,
            sim_time_s=1.0,
            mode=FlightMode.DISARMED,
            armed=False,
            landed=True,
            home_enu_m=(20.0, 2.0, 0.0),
        )
        base.update(kw)
        self._autopilot.publish_status(VehicleStatus(**base))

    def _on_command(self, cmd: Command) -> CommandReply | None:
        with self.lock:
            self.received.append(cmd)
            reply_of = self.replies.get(type(cmd))
        return reply_of(cmd) if reply_of else CommandReply(vehicle_id=self.vid, accepted=True)

    def commands(self, kind: type) -> list[Any]:
        with self.lock:
            return [c for c in self.received if isinstance(c, kind)]

    def stop(self) -> None:
        self._autopilot.close()


@dataclass
class FlowRig:
    """The gateway under test, its MAVLink client, and uav3 as this test plays it."""

    net: Network
    gcs: MavClient
    uav3: ScriptedVehicle
    api_base: int
    log_dir: Path


@pytest.fixture(scope="module")
def swarm(tmp_path_factory: pytest.TempPathFactory) -> Iterator[FlowRig]:
    tmp = tmp_path_factory.mktemp("gateway")
    scenario, gcs_port, api_base = write_scenario(tmp / "scenario.toml", 3)
    with (
        zenoh_network() as (net, _router),
        open_session(net.client) as session,
        vehicles(net, scenario, tmp, ["uav1", "uav2"], speed=3.0, skip=("uav3",)),
        gateway(net, scenario, tmp, "cmd_timeout_s=3") as gw,
    ):
        uav3 = ScriptedVehicle(session, Keys())
        uav3.start()
        try:
            with MavClient(gcs_port) as gcs:
                for sysid in (1, 2):  # statuses arrived: the fake's vehicles are standing by
                    gcs.wait_standby(sysid, 60.0)

                def uav3_ready() -> bool:
                    uav3.publish_status()
                    gcs.pump(0.1)
                    return any(
                        m.get_type() == "HEARTBEAT"
                        and m.get_srcSystem() == UAV3
                        and m.system_status == mavlink.MAV_STATE_STANDBY
                        for m in gcs.inbox
                    )

                wait_until(uav3_ready, 30.0, "uav3's status in its heartbeat")
                yield FlowRig(net, gcs, uav3, api_base, tmp)
                assert gw.poll() is None, "the gateway died during the tests"
        finally:
            uav3.stop()


def ready(c: MavClient, sysid: int) -> None:
    c.drain()
    c.wait_standby(sysid, 60.0)


# ----------------------------------------------------------------------------- connect
def test_qgc_connect_sequence(swarm: FlowRig) -> None:
    c = swarm.gcs
    for sysid in (1, 2, 3):
        hb = c.wait_type("HEARTBEAT", sysid)
        assert hb.get_srcComponent() == 1
        assert (hb.type, hb.autopilot) == (mavlink.MAV_TYPE_QUADROTOR, mavlink.MAV_AUTOPILOT_PX4)
        assert hb.base_mode & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    c.drain()
    assert c.command(1, mavlink.MAV_CMD_REQUEST_MESSAGE, 148) == ACCEPTED
    version = c.wait_type("AUTOPILOT_VERSION", 1)
    for cap in ("MAVLINK2", "MISSION_INT", "COMMAND_INT", "PARAM_ENCODE_BYTEWISE"):
        assert version.capabilities & getattr(mavlink, f"MAV_PROTOCOL_CAPABILITY_{cap}"), cap
    v = version.flight_sw_version
    assert (v >> 24, (v >> 16) & 0xFF, (v >> 8) & 0xFF) >= (1, 4, 1)
    assert c.command(1, mavlink.MAV_CMD_REQUEST_MESSAGE, 300) == ACCEPTED
    assert c.wait_type("PROTOCOL_VERSION", 1).max_version >= 200
    for msg_id in (435, 397, 395):  # AVAILABLE_MODES, COMPONENT_METADATA / INFORMATION
        assert c.command(1, mavlink.MAV_CMD_REQUEST_MESSAGE, msg_id) == UNSUPPORTED
    params = c.params(1)
    counts = {count for _, _, count, _ in params.values()}
    assert counts == {len(params)}
    assert sorted(index for *_, index in params.values()) == list(range(len(params)))
    assert {
        "MIS_TAKEOFF_ALT",
        "RTL_RETURN_ALT",
        "NAV_DLL_ACT",
        "GF_MAX_VER_DIST",
        "GF_MAX_HOR_DIST",
        "MPC_XY_CRUISE",
    } <= set(params)
    items = c.download(1)  # the scenario's mission, as the autopilot has it
    assert [i.command for i in items] == [22, 16, 16, 21]
    assert all(i.frame == mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT for i in items)
    assert items[1].z == pytest.approx(10.0, abs=0.01)
    seen = {m.get_type() for m in c.collect(3.0) if m.get_srcSystem() == 1}
    assert {*FAST_STREAMS, *SLOW_STREAMS_HZ, "HEARTBEAT"} <= seen


def test_telemetry_content(swarm: FlowRig) -> None:
    c = swarm.gcs
    c.drain()
    pos = c.wait_type("GLOBAL_POSITION_INT", 2)
    lat, lon, alt = enu_to_geodetic((20.0, 0.0, 0.0), ORIGIN)  # uav2's spawn
    assert pos.lat == pytest.approx(lat * 1e7, abs=20) and pos.lon == pytest.approx(
        lon * 1e7, abs=20
    )
    assert pos.alt == pytest.approx(alt * 1000, abs=50) and abs(pos.relative_alt) < 50
    att = c.wait_type("ATTITUDE", 2)
    assert math.degrees(att.yaw) == pytest.approx(90.0)  # the fake faces east (ENU identity)
    assert c.wait_type("GPS_RAW_INT", 2).fix_type == mavlink.GPS_FIX_TYPE_3D_FIX
    status = c.wait_type("SYS_STATUS", 2)
    assert status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_PREARM_CHECK
    assert status.onboard_control_sensors_health & mavlink.MAV_SYS_STATUS_SENSOR_GPS
    ext = c.wait_type("EXTENDED_SYS_STATE", 2)
    assert ext.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
    home = c.wait_type("HOME_POSITION", 2, timeout_s=30.0)
    assert home.latitude == pytest.approx(lat * 1e7, abs=20)
    conc = c.wait_type("NAMED_VALUE_FLOAT", 2)
    name = conc.name if isinstance(conc.name, str) else conc.name.decode()
    assert name.rstrip("\0") == "conc_gm3"
    assert 0.0 <= conc.value <= 0.03
    hud = c.wait_type("VFR_HUD", 2)
    assert hud.airspeed == pytest.approx(6.0, abs=0.01)  # standing still in a 6 m/s wind


# ----------------------------------------------------------------------------- flying
def test_qgc_takeoff_then_modes_by_set_mode(swarm: FlowRig) -> None:
    c = swarm.gcs
    ready(c, 1)
    takeoff_amsl = ORIGIN.alt_m + 6.0
    # QGC: NAV_TAKEOFF while disarmed (AMSL, NaN lat/lon), then ARM once accepted
    assert c.command(1, 22, -1, 0, 0, NAN, NAN, NAN, takeoff_amsl) == ACCEPTED
    c.wait_mode(1, 4, 2, armed=False)
    assert c.command(1, 400, 1) == ACCEPTED
    c.wait_mode(1, 4, 3, armed=True)  # took off, holding
    c.wait(
        "GLOBAL_POSITION_INT at 6 m",
        lambda m: (
            m.get_type() == "GLOBAL_POSITION_INT"
            and m.get_srcSystem() == 1
            and abs(m.relative_alt - 6000) < 200
        ),
    )
    c.wait_type("EXTENDED_SYS_STATE", 1, landed_state=mavlink.MAV_LANDED_STATE_IN_AIR)
    c.set_mode(1, 3, 0)  # POSCTL: no RC here: refused, said in a STATUSTEXT, mode unchanged
    c.wait_type("STATUSTEXT", 1)
    c.set_mode(1, 4, 5)  # RTL
    c.wait_mode(1, 4, 5, armed=True)
    c.set_mode(1, 4, 6)  # LAND
    c.wait_mode(1, 4, 6, armed=True)
    c.wait_disarmed(1)
    assert c.command(1, 400, 0) == TEMP_REJECTED  # already disarmed: the autopilot says no


def test_a_command_right_after_arm_follows_the_arm(swarm: FlowRig) -> None:
    """The autopilot publishes its status before replying, but the gateway may handle the reply
    first. A takeoff sent the moment the ARM's ACK arrives (MAVSDK: arm, then takeoff), or while
    the Arm is still on its way, goes to the autopilot after the Arm — it is not kept back as
    a "selected while disarmed" mode that nothing would ever fly (CI saw exactly that)."""
    c, v = swarm.gcs, swarm.uav3
    from swarmbus.messages import Arm, Disarm, Takeoff

    ready(c, UAV3)
    takeoff_amsl = ORIGIN.alt_m + 6.0
    try:
        # 1. ACK before any status says armed: uav3 accepts and keeps publishing "disarmed"
        before = len(v.received)
        assert c.command(UAV3, 400, 1) == ACCEPTED
        assert c.command(UAV3, 22, -1, 0, 0, NAN, NAN, NAN, takeoff_amsl) == ACCEPTED
        wait_until(
            lambda: v.commands(Takeoff) != [] and len(v.received) >= before + 2,
            10.0,
            "the takeoff on the bus",
        )
        assert [type(m) for m in v.received[before:] if isinstance(m, (Arm, Takeoff))] == [
            Arm,
            Takeoff,
        ]
        assert c.command(UAV3, 400, 0) == ACCEPTED  # Disarm: selections work as before again
        # 2. the Arm still on its way when the takeoff comes
        v.replies[Arm] = _accept_after(0.5)
        before = len(v.received)
        c.drain()
        c.send(UAV3, mavlink.MAVLink_command_long_message(UAV3, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
        c.send(
            UAV3,
            mavlink.MAVLink_command_long_message(
                UAV3, 1, 22, 0, -1, 0, 0, NAN, NAN, NAN, takeoff_amsl
            ),
        )
        assert c.wait_type("COMMAND_ACK", UAV3, command=400).result == ACCEPTED
        assert c.wait_type("COMMAND_ACK", UAV3, command=22).result == ACCEPTED
        wait_until(lambda: len(v.received) >= before + 2, 10.0, "arm and takeoff on the bus")
        assert [type(m) for m in v.received[before:] if isinstance(m, (Arm, Takeoff))] == [
            Arm,
            Takeoff,
        ]
    finally:
        v.replies.pop(Arm, None)
        assert c.command(UAV3, 400, 0) == ACCEPTED
        assert isinstance(v.received[-1], Disarm)


def test_mission_upload_start_reached_and_download(swarm: FlowRig) -> None:
    c = swarm.gcs
    ready(c, 2)
    places = [enu_to_geodetic(p, ORIGIN) for p in [(20, 0, 0), (26, 0, 0), (26, 4, 0), (22, 4, 0)]]
    items = [
        mission_item(2, 0, 22, *places[0][:2], 5.0),
        mission_item(2, 1, 16, *places[1][:2], 5.0),
        mavlink.MAVLink_mission_item_int_message(2, 1, 2, 2, 178, 0, 1, 1, 4.0, -1, 0, 0, 0, 0, 0),
        mission_item(2, 3, 16, *places[2][:2], 6.0),
        mission_item(2, 4, 21, *places[3][:2], 0.0),
    ]
    assert c.upload(2, items) == mavlink.MAV_MISSION_ACCEPTED
    down = c.download(2)
    assert [(d.command, d.x, d.y, d.z) for d in down] == [(i.command, i.x, i.y, i.z) for i in items]
    # QGC's start mission: SET_MODE mission while disarmed, then ARM
    c.set_mode(2, 4, 4)
    c.wait_mode(2, 4, 4, armed=False)
    assert c.command(2, 400, 1) == ACCEPTED
    reached: list[int] = []
    while len(reached) < 4:
        reached.append(c.wait_type("MISSION_ITEM_REACHED", 2, timeout_s=60.0).seq)
    assert reached == [0, 1, 3, 4]  # MAVLink seqs: the speed item is not a place
    current = c.wait_type("MISSION_CURRENT", 2)
    assert current.total == 5
    c.wait_disarmed(2)


def test_mission_protocol_errors(swarm: FlowRig) -> None:
    c = swarm.gcs
    v = swarm.uav3
    lat, lon, _ = enu_to_geodetic((20, 2, 0), ORIGIN)

    def ack(count: int, mission_type: int = 0) -> int:
        c.send(UAV3, mavlink.MAVLink_mission_count_message(UAV3, 1, count, mission_type))
        return int(c.wait_type("MISSION_ACK", UAV3).type)

    assert ack(65535) == mavlink.MAV_MISSION_NO_SPACE
    assert ack(3, 7) == mavlink.MAV_MISSION_UNSUPPORTED  # no such mission type
    c.send(UAV3, mavlink.MAVLink_mission_count_message(UAV3, 1, 3, 0))
    assert c.wait_type("MISSION_REQUEST_INT", UAV3).seq == 0
    c.send(UAV3, mission_item(UAV3, 0, 16, lat, lon, 5))
    assert c.wait_type("MISSION_REQUEST_INT", UAV3).seq == 1
    c.send(UAV3, mission_item(UAV3, 2, 16, lat, lon, 5))  # skips item 1
    assert c.wait_type("MISSION_ACK", UAV3).type == mavlink.MAV_MISSION_INVALID_SEQUENCE
    bad = mission_item(UAV3, 0, 16, lat, lon, 5)
    bad.command = 31000
    assert c.upload(UAV3, [bad]) == mavlink.MAV_MISSION_UNSUPPORTED
    assert not v.commands(MissionUpload)  # nothing reached the autopilot so far
    v.replies[MissionUpload] = lambda cmd: CommandReply(
        vehicle_id="uav3", accepted=False, code=RejectCode.DENIED, reason="a mission is flying"
    )
    assert c.upload(UAV3, [mission_item(UAV3, 0, 16, lat, lon, 5)]) == mavlink.MAV_MISSION_DENIED
    v.replies.pop(MissionUpload)
    assert c.upload(UAV3, [mission_item(UAV3, 0, 16, lat, lon, 5)]) == mavlink.MAV_MISSION_ACCEPTED
    (sent,) = v.commands(MissionUpload)[-1:]
    assert (sent.items[0].x, sent.items[0].y, sent.items[0].z) == pytest.approx(
        (20, 2, 5), abs=0.01
    )
    c.send(UAV3, mavlink.MAVLink_mission_clear_all_message(UAV3, 1, 0))
    assert c.wait_type("MISSION_ACK", UAV3).type == mavlink.MAV_MISSION_ACCEPTED


# ----------------------------------------------------------------------------- results
def test_command_results_follow_the_autopilot(swarm: FlowRig) -> None:
    c, v = swarm.gcs, swarm.uav3
    cases = [
        (RejectCode.DENIED, TEMP_REJECTED),
        (RejectCode.INVALID, DENIED),
        (RejectCode.UNSUPPORTED, UNSUPPORTED),
        (RejectCode.FAILED, FAILED),
    ]
    from swarmbus.messages import Land

    for code, result in cases:
        v.replies[Land] = _refuse_with(code)
        assert c.command(UAV3, mavlink.MAV_CMD_NAV_LAND) == result
    v.replies[Land] = lambda cmd: None  # no reply at all: FAILED after the gateway's timeout
    assert c.command(UAV3, mavlink.MAV_CMD_NAV_LAND) == FAILED
    v.replies.pop(Land)
    assert c.command(UAV3, mavlink.MAV_CMD_NAV_LAND) == ACCEPTED
    assert c.command(UAV3, 31000) == UNSUPPORTED


def test_a_retried_command_waits_for_one_answer(swarm: FlowRig) -> None:
    c, v = swarm.gcs, swarm.uav3
    from swarmbus.messages import ReturnToLaunch

    v.replies[ReturnToLaunch] = _accept_after(0.3)
    msg = mavlink.MAVLink_command_long_message(UAV3, 1, 20, 0, 0, 0, 0, 0, 0, 0, 0)
    before = len(v.commands(ReturnToLaunch))
    c.send(UAV3, msg)
    c.send(UAV3, msg)  # MAVSDK and QGC retry after 0.5 s / 1.3 s without an ACK
    assert c.wait_type("COMMAND_ACK", UAV3, command=20).result == ACCEPTED
    assert len(v.commands(ReturnToLaunch)) == before + 1
    v.replies.pop(ReturnToLaunch)


def test_parameters_are_the_autopilots(swarm: FlowRig) -> None:
    c, v = swarm.gcs, swarm.uav3
    real32, int32 = mavlink.MAV_PARAM_TYPE_REAL32, mavlink.MAV_PARAM_TYPE_INT32
    v.replies[SetParam] = lambda cmd: CommandReply(
        vehicle_id="uav3", accepted=True, params={cmd.name: cmd.value}
    )
    assert c.param_set(UAV3, "RTL_RETURN_ALT", 22.5, real32).param_value == 22.5
    assert v.commands(SetParam)[-1] == SetParam(name="RTL_RETURN_ALT", value=22.5)
    assert c.param_set(UAV3, "NAV_DLL_ACT", float_bits_of_int(3), int32).param_value == (
        float_bits_of_int(3)
    )
    assert v.commands(SetParam)[-1] == SetParam(name="NAV_DLL_ACT", value=3.0)
    count = len(v.commands(SetParam))
    assert c.param_set(UAV3, "RTL_RETURN_ALT", NAN, real32).param_value == 22.5  # refused
    assert len(v.commands(SetParam)) == count  # never reached the autopilot
    v.replies[SetParam] = lambda cmd: CommandReply(
        vehicle_id="uav3", accepted=False, code=RejectCode.INVALID, reason="outside the fence"
    )
    assert c.param_set(UAV3, "GF_MAX_HOR_DIST", 5.0, real32).param_value != 5.0
    v.replies[SetParam] = lambda cmd: CommandReply(
        vehicle_id="uav3", accepted=False, code=RejectCode.UNSUPPORTED, reason="unknown"
    )
    assert c.param_set(UAV3, "MPC_XY_CRUISE", 3.0, real32).param_value == 3.0  # gateway-side
    v.replies.pop(SetParam)
    assert v.commands(GetParams), "the gateway never asked the autopilot for its parameters"


def test_message_intervals(swarm: FlowRig) -> None:
    c = swarm.gcs
    assert c.command(2, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 100_000) == ACCEPTED
    assert c.command(2, mavlink.MAV_CMD_GET_MESSAGE_INTERVAL, 30) == ACCEPTED
    assert c.wait_type("MESSAGE_INTERVAL", 2, message_id=30).interval_us == 100_000
    assert c.command(2, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 12345, 100_000) == DENIED
    assert c.command(2, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 0) == ACCEPTED


def test_gcs_heartbeats_reach_the_autopilot(swarm: FlowRig) -> None:
    c, v = swarm.gcs, swarm.uav3
    before = len(v.commands(GcsHeartbeat))
    c.heartbeat()
    wait_until(lambda: len(v.commands(GcsHeartbeat)) > before, 10.0, "a GcsHeartbeat on the bus")


# ----------------------------------------------------------------------------- hostile
def test_hostile_frames_never_hurt_the_gateway(swarm: FlowRig) -> None:
    c, v = swarm.gcs, swarm.uav3
    from swarmbus.messages import Arm

    arms = len(v.commands(Arm))
    good = mavlink.MAVLink_command_long_message(UAV3, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
    from gcs_bridge.dialect import pack

    frame = bytearray(pack(c.mav, good))
    frame[-1] ^= 0x55  # bad CRC
    for junk in (b"", b"\xfd", b"\xfd\xff" + bytes(300), bytes(frame), os.urandom(200)):
        c.send_raw(UAV3, junk)
    c.send(UAV3, mavlink.MAVLink_command_long_message(99, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    c.send(UAV3, mavlink.MAVLink_command_long_message(UAV3, 55, 400, 0, 1, 0, 0, 0, 0, 0, 0))
    c.send(UAV3, mavlink.MAVLink_param_set_message(UAV3, 1, b"NAV_DLL_ACT", NAN, 6))
    c.send(UAV3, mavlink.MAVLink_param_set_message(UAV3, 1, b"NO_SUCH_PARAM", 1.0, 9))
    c.send(
        UAV3,
        mavlink.MAVLink_mission_item_int_message(UAV3, 1, 7, 6, 16, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0),
    )
    c.send(UAV3, mavlink.MAVLink_mission_request_int_message(UAV3, 1, 60000, 0))
    c.send(UAV3, mavlink.MAVLink_set_mode_message(UAV3, 255, 0xFFFFFFFF))
    c.send(
        UAV3,
        mavlink.MAVLink_command_long_message(UAV3, 1, 22, 0, NAN, NAN, NAN, NAN, NAN, NAN, 1e30),
    )
    assert c.command(UAV3, mavlink.MAV_CMD_REQUEST_MESSAGE, 148) == ACCEPTED
    assert len(v.commands(Arm)) == arms  # no wrongly addressed or corrupt ARM got through
    for sysid in (1, 2, 3):
        c.wait_type("HEARTBEAT", sysid)
