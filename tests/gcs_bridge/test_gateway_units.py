"""Unit tests of the gateway's pure logic: modes, frames, parameters, commands, telemetry."""

from __future__ import annotations

import math

import pytest

from gcs_bridge.commands import (
    ACCEPTED,
    DENIED,
    FAILED,
    TEMPORARILY_REJECTED,
    UNSUPPORTED,
    CommandRequest,
    Facts,
    result_of_reply,
    translate,
    translate_mode,
)
from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import (
    course_deg,
    enu_to_geodetic,
    enu_to_ned,
    enu_yaw_deg_of_heading,
    euler_ned_frd,
    flu_to_frd,
    geodetic_to_enu,
)
from gcs_bridge.modes import (
    Px4AutoSub,
    Px4Main,
    base_mode_of,
    custom_mode_of,
    decode_custom_mode,
    encode_custom_mode,
    flight_mode_for,
    mav_type_of,
)
from gcs_bridge.offboard import Here
from gcs_bridge.params import INT32, ParamError, ParamTable, float_bits_of_int
from gcs_bridge.telemetry import StreamSchedule, landed_state_of
from swarmbus.messages import (
    Arm,
    CommandReply,
    Disarm,
    FlightMode,
    Goto,
    Hold,
    Land,
    MissionStart,
    RejectCode,
    SetMode,
    Takeoff,
)
from swarmbus.scenario import Failsafe, Origin
from swarmbus.vehicle_types import load_vehicle_type
from tests.support.messages_samples import vehicle_status as status

ORIGIN = Origin()
S2 = math.sqrt(0.5)


# ----------------------------------------------------------------------------- modes
def test_custom_mode_is_px4_main_and_sub_packed() -> None:
    assert encode_custom_mode(4, 4) == (4 << 16) | (4 << 24)
    m = decode_custom_mode(encode_custom_mode(Px4Main.AUTO, Px4AutoSub.RTL))
    assert (m.main, m.sub) == (4, 5)
    assert decode_custom_mode(encode_custom_mode(Px4Main.OFFBOARD)).main == 6


@pytest.mark.parametrize(
    ("mode", "main", "sub"),
    [
        (FlightMode.MISSION, 4, 4),
        (FlightMode.TAKEOFF, 4, 2),
        (FlightMode.HOLD, 4, 3),
        (FlightMode.RTL, 4, 5),
        (FlightMode.LAND, 4, 6),
        (FlightMode.OFFBOARD, 6, 0),
        (FlightMode.DISARMED, 4, 3),
    ],
)
def test_heartbeat_mode_mirrors_the_autopilot_mode(mode: FlightMode, main: int, sub: int) -> None:
    m = decode_custom_mode(custom_mode_of(status(mode=mode)))
    assert (m.main, m.sub) == (main, sub)
    if mode not in (FlightMode.DISARMED, FlightMode.ARMED):
        assert flight_mode_for(main, sub) == mode


def test_base_mode_has_custom_bit_and_armed_bit_only_when_armed() -> None:
    assert base_mode_of(status()) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert not base_mode_of(status()) & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    assert base_mode_of(status(armed=True)) & mavlink.MAV_MODE_FLAG_SAFETY_ARMED


def test_manual_modes_have_no_autopilot_mode_and_kind_and_rotors_pick_mav_type() -> None:
    assert flight_mode_for(Px4Main.MANUAL, 0) is None  # no RC: no stick-only modes
    assert flight_mode_for(Px4Main.ALTCTL, 0) is None
    assert flight_mode_for(Px4Main.AUTO, 0) is None

    def mav_type(name: str) -> int:
        t = load_vehicle_type(name)
        return mav_type_of(t.kind, len(t.rotors))

    assert mav_type("iris") == mavlink.MAV_TYPE_QUADROTOR == 2
    assert mav_type("typhoon_h480") == mavlink.MAV_TYPE_HEXAROTOR == 13
    assert mav_type("aerosonde") == mavlink.MAV_TYPE_FIXED_WING == 1


# ----------------------------------------------------------------------------- frames
def test_level_vehicle_facing_east_has_ned_yaw_90() -> None:
    roll, pitch, yaw = euler_ned_frd((0.0, 0.0, 0.0, 1.0))
    assert roll == pytest.approx(0.0) and pitch == pytest.approx(0.0)
    assert math.degrees(yaw) == pytest.approx(90.0)


def test_facing_north_is_ned_yaw_0() -> None:
    # 90° about ENU z: body x (forward) points north
    _, _, yaw = euler_ned_frd((0.0, 0.0, S2, S2))
    assert math.degrees(yaw) == pytest.approx(0.0, abs=1e-9)


def test_nose_up_is_positive_pitch_and_right_wing_down_is_positive_roll() -> None:
    # rotation of -30° about body y (left): the nose rises
    a = math.radians(-30.0) / 2
    _, pitch, _ = euler_ned_frd((0.0, math.sin(a), 0.0, math.cos(a)))
    assert math.degrees(pitch) == pytest.approx(30.0)
    # rotation of +20° about body x (forward): the left wing rises, the right one drops
    b = math.radians(20.0) / 2
    roll, _, _ = euler_ned_frd((math.sin(b), 0.0, 0.0, math.cos(b)))
    assert math.degrees(roll) == pytest.approx(20.0)


def test_vectors_and_rates_change_frame() -> None:
    assert enu_to_ned((1.0, 2.0, 3.0)) == (2.0, 1.0, -3.0)
    assert flu_to_frd((0.1, 0.2, 0.3)) == (0.1, -0.2, -0.3)
    assert course_deg((1.0, 0.0, 0.0)) == pytest.approx(90.0)
    assert enu_yaw_deg_of_heading(0.0) == pytest.approx(90.0)
    assert enu_yaw_deg_of_heading(90.0) == pytest.approx(0.0)


def test_geodetic_round_trip_near_the_origin() -> None:
    lat, lon, alt = enu_to_geodetic((100.0, -50.0, 10.0), ORIGIN)
    assert alt == pytest.approx(ORIGIN.alt_m + 10.0, abs=0.01)
    assert lat < ORIGIN.lat_deg and lon > ORIGIN.lon_deg
    e, n, u = geodetic_to_enu(lat, lon, alt, ORIGIN)
    assert (e, n, u) == pytest.approx((100.0, -50.0, 10.0), abs=1e-6)


# ----------------------------------------------------------------------------- params
def table() -> ParamTable:
    return ParamTable(
        Failsafe(takeoff_altitude_m=7.0, datalink_loss_action="land"), load_vehicle_type("iris")
    )


def test_params_start_from_the_scenario_and_have_stable_indices() -> None:
    t = table()
    assert t.value("MIS_TAKEOFF_ALT") == 7.0
    assert t.value("NAV_DLL_ACT") == 3.0  # PX4: 3 = land
    names = [s.name for s in t.specs]
    assert len(set(names)) == t.count and all(len(n) <= 16 for n in names)
    assert t.index_of("RTL_RETURN_ALT") == names.index("RTL_RETURN_ALT")
    for required in ("GF_MAX_VER_DIST", "GF_MAX_HOR_DIST", "MPC_XY_CRUISE", "NAV_DLL_ACT"):
        assert required in names


def test_int_params_travel_bytewise() -> None:
    t = table()
    spec = t.spec("NAV_DLL_ACT")
    assert spec is not None and spec.param_type == INT32
    assert t.wire_value("NAV_DLL_ACT") == float_bits_of_int(3)
    assert t.decode_set("NAV_DLL_ACT", float_bits_of_int(2)) == 2.0  # QGC / MAVSDK
    assert t.decode_set("NAV_DLL_ACT", 1.0) == 1.0  # MAVProxy casts


@pytest.mark.parametrize("bad", [math.nan, math.inf, -1.0, 1e9])
def test_non_finite_and_out_of_range_values_are_refused(bad: float) -> None:
    with pytest.raises(ParamError):
        table().decode_set("MIS_TAKEOFF_ALT", bad)
    with pytest.raises(ParamError):
        table().decode_set("NAV_DLL_ACT", bad)


def test_autopilot_values_replace_scenario_values() -> None:
    t = table()
    t.merge_from_autopilot({"RTL_RETURN_ALT": 33.0, "SOMETHING_ELSE": 1.0})
    assert t.value("RTL_RETURN_ALT") == 33.0 and "RTL_RETURN_ALT" in t.backed


# ----------------------------------------------------------------------------- commands
def facts(**kw: object) -> Facts:
    base: dict[str, object] = dict(
        origin=ORIGIN,
        home_amsl_m=ORIGIN.alt_m,
        home_enu=(0.0, 0.0, 0.0),
        position_enu=(5.0, 6.0, 0.0),
        landed=True,
        takeoff_altitude_m=10.0,
        mission_seqs=[0, 2, 3],
    )
    base.update(kw)
    return Facts(**base)  # type: ignore[arg-type]


TAKEOFF = int(mavlink.MAV_CMD_NAV_TAKEOFF)


@pytest.mark.parametrize(
    ("req", "altitude"),
    [
        (CommandRequest(TAKEOFF, z=ORIGIN.alt_m + 12.0), 12.0),  # QGC: AMSL, NaN lat/lon
        (CommandRequest(TAKEOFF), 10.0),  # MAVSDK: NaN → MIS_TAKEOFF_ALT
        (CommandRequest(TAKEOFF, x=0.0, y=0.0, z=8.0), 8.0),  # MAVProxy: relative, lat/lon 0
        (CommandRequest(TAKEOFF, z=5.0, frame=int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)), 5.0),
    ],
)
def test_takeoff_altitude_semantics_of_each_client(req: CommandRequest, altitude: float) -> None:
    t = translate(req, facts())
    assert t is not None and isinstance(t.bus, Takeoff)
    assert t.bus.altitude_m == pytest.approx(altitude)


def test_takeoff_below_home_is_refused_not_sent() -> None:
    t = translate(CommandRequest(TAKEOFF, z=ORIGIN.alt_m - 5.0), facts())
    assert t is not None and t.bus is None and t.result == DENIED


@pytest.mark.parametrize("z", [math.inf, -math.inf])
def test_an_infinite_takeoff_altitude_is_refused_not_the_default(z: float) -> None:
    """Only NaN means "absent" (MIS_TAKEOFF_ALT); found by tests/gcs_bridge/test_gateway_fuzz.py."""
    t = translate(CommandRequest(TAKEOFF, z=z), facts())
    assert t is not None and t.bus is None and t.result == DENIED


@pytest.mark.parametrize(
    ("x", "y", "z"),
    [(math.inf, 8.0, 500.0), (47.0, -math.inf, 500.0), (math.nan, math.nan, math.inf)],
)
def test_an_infinite_reposition_is_refused_not_kept(x: float, y: float, z: float) -> None:
    rep = int(mavlink.MAV_CMD_DO_REPOSITION)
    t = translate(CommandRequest(rep, -1.0, 1.0, 0.0, math.nan, x, y, z), facts())
    assert t is not None and t.bus is None and t.result == DENIED


def test_arm_disarm_and_forced_disarm_in_the_air() -> None:
    arm = int(mavlink.MAV_CMD_COMPONENT_ARM_DISARM)
    t = translate(CommandRequest(arm, 1.0), facts())
    assert t is not None and isinstance(t.bus, Arm)
    t = translate(CommandRequest(arm, 0.0, 0.0), facts(landed=False))
    assert t is not None and t.bus is None and t.result == TEMPORARILY_REJECTED
    t = translate(CommandRequest(arm, 0.0, 21196.0), facts(landed=False))
    assert t is not None and isinstance(t.bus, Disarm) and t.bus.force
    t = translate(CommandRequest(arm, math.nan), facts())
    assert t is not None and t.result == DENIED


def test_reposition_without_position_holds_and_with_one_goes_there() -> None:
    rep = int(mavlink.MAV_CMD_DO_REPOSITION)
    t = translate(CommandRequest(rep, -1.0, 1.0), facts())
    assert t is not None and isinstance(t.bus, Hold)
    lat, lon, alt = enu_to_geodetic((30.0, 40.0, 15.0), ORIGIN)
    t = translate(CommandRequest(rep, -1.0, 1.0, 0.0, math.nan, lat, lon, alt), facts())
    assert t is not None and isinstance(t.bus, Goto)
    assert t.bus.position_enu_m == pytest.approx((30.0, 40.0, 15.0), abs=0.05)
    t = translate(
        CommandRequest(rep, z=20.0, frame=int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)), facts()
    )
    assert t is not None and isinstance(t.bus, Goto)
    assert t.bus.position_enu_m == pytest.approx((5.0, 6.0, 20.0), abs=1e-6)


def test_mode_commands_map_to_bus_commands() -> None:
    custom = float(mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
    assert isinstance(translate_mode(custom, 4, 4, facts()).bus, SetMode)
    assert isinstance(translate_mode(custom, 4, 6, facts()).bus, Land)
    t = translate_mode(custom, 4, 2, facts())
    assert isinstance(t.bus, Takeoff) and t.bus.altitude_m == 10.0
    assert translate_mode(0.0, 4, 4, facts()).result == DENIED
    assert translate_mode(custom, 2, 0, facts()).result == DENIED  # ALTCTL: no RC
    position = translate_mode(custom, 3, 0, facts()).bus  # POSCTL: flown from MANUAL_CONTROL
    assert isinstance(position, SetMode) and position.mode == FlightMode.POSITION
    assert translate_mode(custom, math.nan, 0, facts()).result == DENIED


def test_mission_start_speaks_mavlink_seqs() -> None:
    t = translate(CommandRequest(int(mavlink.MAV_CMD_MISSION_START), 2.0), facts())
    assert t is not None and isinstance(t.bus, MissionStart) and t.bus.start_index == 1


def test_unknown_commands_are_not_flight_commands() -> None:
    assert translate(CommandRequest(31000), facts()) is None


@pytest.mark.parametrize(
    ("code", "result"),
    [
        (RejectCode.DENIED, TEMPORARILY_REJECTED),
        (RejectCode.INVALID, DENIED),
        (RejectCode.UNSUPPORTED, UNSUPPORTED),
        (RejectCode.FAILED, FAILED),
    ],
)
def test_reject_codes_become_mav_results(code: RejectCode, result: int) -> None:
    assert result_of_reply(CommandReply(vehicle_id="a", accepted=False, code=code)) == result
    assert result_of_reply(CommandReply(vehicle_id="a", accepted=True)) == ACCEPTED


# ----------------------------------------------------------------------------- telemetry
def test_schedule_rate_is_per_sim_second_and_honours_intervals() -> None:
    att = int(mavlink.MAVLINK_MSG_ID_ATTITUDE)
    sched = StreamSchedule({att: 4.0})
    ticks = [k / 120.0 for k in range(0, 1201)]  # 10 sim seconds at 120 Hz
    assert sum(att in sched.due(t) for t in ticks) == pytest.approx(41, abs=1)
    assert sched.set_interval_us(att, 50_000)  # 20 Hz
    sched2_count = sum(att in sched.due(10.0 + t) for t in ticks[1:])
    assert sched2_count == pytest.approx(200, abs=2)
    assert sched.set_interval_us(att, -1) and sched.interval_us(att) == -1
    assert not any(att in sched.due(30.0 + t) for t in ticks)
    assert not sched.set_interval_us(12345, 1000)


def test_schedule_never_bursts_after_a_gap_and_restarts_with_the_sim() -> None:
    att = int(mavlink.MAVLINK_MSG_ID_ATTITUDE)
    sched = StreamSchedule({att: 10.0})
    assert sched.due(0.0) == [att]
    assert sched.due(5.0) == [att]  # 50 intervals late: one message, not 50
    assert sched.due(5.05) == []
    assert sched.due(0.0) == [att]  # sim time went back: a new simulation


def test_landed_state_for_mavsdk_in_air() -> None:
    assert landed_state_of(status()) == mavlink.MAV_LANDED_STATE_ON_GROUND
    st = status(mode=FlightMode.TAKEOFF, armed=True, landed=False)
    assert landed_state_of(st) == mavlink.MAV_LANDED_STATE_TAKEOFF
    st = status(mode=FlightMode.HOLD, armed=True, landed=False)
    assert landed_state_of(st) == mavlink.MAV_LANDED_STATE_IN_AIR
    assert landed_state_of(None) == mavlink.MAV_LANDED_STATE_UNDEFINED


def test_a_long_statustext_travels_as_mavlink2_chunks() -> None:
    from gcs_bridge.core import statustext_chunks

    short = statustext_chunks("uav1: fits in one", 7)
    assert len(short) == 1 and short[0].id == 0
    text = "uav1: item 12: GF_MAX_HOR_DIST 500 m: 551.2 m from home, mission refused"
    chunks = statustext_chunks(text, 7)
    assert [(c.id, c.chunk_seq) for c in chunks] == [(7, 0), (7, 1)]
    joined = b"".join(
        c.text if isinstance(c.text, bytes) else c.text.encode() for c in chunks
    ).rstrip(b"\0")
    assert joined.decode() == text
    exactly_two = statustext_chunks("x" * 100, 9)  # the receiver needs a short last chunk
    assert [c.chunk_seq for c in exactly_two] == [0, 1, 2]
    assert len(statustext_chunks("y" * 5000, 3)) == 4  # capped


# ------------------------------------------------------------------ offboard setpoints
def _here(yaw_enu_rad: float = 0.0) -> Here:

    return Here(
        position_enu=(25.0, -1.0, 6.0),
        yaw_enu_rad=yaw_enu_rad,
        local_origin_enu=(20.0, -4.0, 0.0),
        home_amsl_m=Origin().alt_m,
        origin=Origin(),
    )


def _local_target(frame: int, mask: int, pos: tuple, vel: tuple = (0, 0, 0), **kw: float) -> object:
    return mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, frame, mask, *pos, *vel, 0, 0, 0, kw.get("yaw", 0.0), kw.get("yaw_rate", 0.0)
    )


def test_local_ned_is_measured_from_the_vehicles_own_origin_with_velocity_feed_forward() -> None:
    from gcs_bridge.offboard import IGNORE_ACCELERATION, IGNORE_YAW_RATE, from_local_ned

    msg = _local_target(1, IGNORE_ACCELERATION | IGNORE_YAW_RATE, (1.0, 2.0, -3.0), (0.5, 0, 0))
    sp = from_local_ned(msg, _here())
    assert sp is not None
    assert sp.position_enu_m == pytest.approx((22.0, -3.0, 3.0))  # spawn (20, -4, 0) + NED
    assert sp.velocity_enu_m_s == pytest.approx((0.0, 0.5, 0.0))  # kept: feed-forward
    assert sp.yaw_deg == pytest.approx(90.0)  # NED yaw 0 (north) is ENU 90


@pytest.mark.parametrize(
    ("yaw_enu_deg", "forward_right", "east_north"),
    [
        (90.0, (2.0, 0.0), (0.0, 2.0)),  # facing north: forward is north
        (90.0, (0.0, 1.0), (1.0, 0.0)),  # facing north: right is east
        (0.0, (2.0, 0.0), (2.0, 0.0)),  # facing east: forward is east
        (0.0, (0.0, 1.0), (0.0, -1.0)),  # facing east: right is south
    ],
)
def test_body_frame_velocity_turns_with_the_heading(
    yaw_enu_deg: float, forward_right: tuple, east_north: tuple
) -> None:
    from gcs_bridge.offboard import (
        FRAME_BODY_NED,
        IGNORE_ACCELERATION,
        IGNORE_POSITION,
        IGNORE_YAW,
        from_local_ned,
    )

    mask = IGNORE_POSITION | IGNORE_ACCELERATION | IGNORE_YAW
    msg = _local_target(FRAME_BODY_NED, mask, (0, 0, 0), (*forward_right, -0.5), yaw_rate=0.2)
    sp = from_local_ned(msg, _here(math.radians(yaw_enu_deg)))
    assert sp is not None and sp.position_enu_m is None
    assert sp.velocity_enu_m_s == pytest.approx((*east_north, 0.5), abs=1e-9)
    assert sp.yaw_rate_deg_s == pytest.approx(-math.degrees(0.2))  # clockwise in NED


def test_body_offset_position_is_relative_to_the_vehicle() -> None:
    from gcs_bridge.offboard import FRAME_BODY_OFFSET_NED, IGNORE_ACCELERATION, from_local_ned

    msg = _local_target(FRAME_BODY_OFFSET_NED, IGNORE_ACCELERATION, (3.0, 0.0, -1.0))
    sp = from_local_ned(msg, _here(math.radians(90.0)))  # facing north, at (25, -1, 6)
    assert sp is not None and sp.position_enu_m == pytest.approx((25.0, 2.0, 7.0))


def test_acceleration_alone_and_global_setpoints() -> None:
    from gcs_bridge.offboard import (
        FRAME_GLOBAL_RELATIVE_ALT_INT,
        IGNORE_POSITION,
        IGNORE_VELOCITY,
        from_global_int,
        from_local_ned,
    )

    acc = mavlink.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, 1, IGNORE_POSITION | IGNORE_VELOCITY, 0, 0, 0, 0, 0, 0, 1.0, 0.0, 0.0, 0, 0
    )
    sp = from_local_ned(acc, _here())
    assert sp is not None and sp.acceleration_enu_m_s2 == pytest.approx((0.0, 1.0, -0.0))
    assert sp.position_enu_m is None and sp.velocity_enu_m_s is None
    lat, lon, _ = enu_to_geodetic((30.0, 40.0, 0.0), Origin())
    glob = mavlink.MAVLink_set_position_target_global_int_message(
        0,
        1,
        1,
        FRAME_GLOBAL_RELATIVE_ALT_INT,
        0b111111000,
        round(lat * 1e7),
        round(lon * 1e7),
        7.0,
        0,
        0,
        0,
        0,
        0,
        0,
        0.0,
        0.0,
    )
    sp = from_global_int(glob, _here())
    assert sp is not None and sp.position_enu_m == pytest.approx((30.0, 40.0, 7.0), abs=0.02)


def _quat_ned(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """w, x, y, z of ZYX Euler angles (the MAVLink / PX4 convention)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (
        cr * cp * cy + sr * sp * sy,
        sr * cp * cy - cr * sp * sy,
        cr * sp * cy + sr * cp * sy,
        cr * cp * sy - sr * sp * cy,
    )


@pytest.mark.parametrize("euler_deg", [(0, 0, 0), (0, -10, 0), (5, 0, 90), (-8, 12, -135)])
def test_attitude_targets_become_the_same_attitude_in_enu(euler_deg: tuple) -> None:
    from gcs_bridge.offboard import IGNORE_BODY_RATES, from_attitude_target

    euler = tuple(math.radians(a) for a in euler_deg)
    msg = mavlink.MAVLink_set_attitude_target_message(
        0, 1, 1, IGNORE_BODY_RATES, list(_quat_ned(*euler)), 0, 0, 0, 0.6
    )
    sp = from_attitude_target(msg)
    assert sp is not None and sp.thrust == pytest.approx(0.6)
    assert sp.attitude_xyzw is not None
    assert euler_ned_frd(sp.attitude_xyzw) == pytest.approx(euler, abs=1e-9)


def test_rate_targets_flip_to_flu_and_a_missing_thrust_is_unusable() -> None:
    from gcs_bridge.offboard import IGNORE_ATTITUDE, IGNORE_THRUST, from_attitude_target

    msg = mavlink.MAVLink_set_attitude_target_message(
        0, 1, 1, IGNORE_ATTITUDE, [1, 0, 0, 0], 0.1, 0.2, 0.3, 0.5
    )
    sp = from_attitude_target(msg)
    assert sp is not None and sp.body_rates_rad_s == pytest.approx((0.1, -0.2, -0.3))
    msg.type_mask = IGNORE_ATTITUDE | IGNORE_THRUST
    assert from_attitude_target(msg) is None
    msg.type_mask, msg.thrust = IGNORE_ATTITUDE, math.nan
    assert from_attitude_target(msg) is None


def test_orbit_command_takes_px4s_signs_and_defaults() -> None:
    from swarmbus.messages import Orbit, OrbitYaw

    f = facts(landed=False)
    lat, lon, _ = enu_to_geodetic((30.0, 10.0, 0.0), Origin())
    t = translate(CommandRequest(34, -8.0, 2.0, 3.0, 0.0, lat, lon, math.nan), f)
    assert t is not None and isinstance(t.bus, Orbit)
    assert t.bus.radius_m == 8.0 and t.bus.speed_m_s == -2.0  # negative radius: anticlockwise
    assert t.bus.yaw == OrbitYaw.TANGENT
    assert t.bus.center_enu_m[:2] == pytest.approx((30.0, 10.0), abs=0.05)
    d = translate(CommandRequest(34), f)
    assert d is not None and isinstance(d.bus, Orbit)
    assert (d.bus.radius_m, d.bus.speed_m_s) == (10.0, 1.0)
    bad = translate(CommandRequest(34, math.inf), f)
    assert bad is not None and bad.bus is None and bad.result == DENIED


def test_manual_control_sticks_become_px4_position_mode_velocities() -> None:
    from gcs_bridge.modes import flight_mode_for
    from gcs_bridge.offboard import from_manual_control
    from swarmbus.messages import FlightMode

    facing_north = _here(math.radians(90.0))
    msg = mavlink.MAVLink_manual_control_message(1, 500, 0, 500, 0, 0)
    sp = from_manual_control(msg, facing_north)  # half forward stick, throttle centred
    assert sp is not None and sp.velocity_enu_m_s == pytest.approx((0.0, 5.0, 0.0), abs=1e-9)
    msg = mavlink.MAVLink_manual_control_message(1, 0, 1000, 1000, -1000, 0)
    sp = from_manual_control(msg, facing_north)  # full right, full throttle, yaw left
    assert sp is not None and sp.velocity_enu_m_s == pytest.approx((10.0, 0.0, 3.0), abs=1e-9)
    assert sp.yaw_rate_deg_s == 150.0  # yaw stick left: counter-clockwise, positive in ENU
    centred = from_manual_control(
        mavlink.MAVLink_manual_control_message(1, 0, 0, 500, 0, 0), facing_north
    )
    assert centred is not None and centred.velocity_enu_m_s == (0.0, 0.0, 0.0)
    assert flight_mode_for(3, 0) == FlightMode.POSITION and flight_mode_for(3, 1) is None


def test_follow_target_puts_the_follower_behind_a_moving_target_facing_it() -> None:
    from gcs_bridge.offboard import Follow, from_follow_target

    lat, lon, _ = enu_to_geodetic((40.0, 30.0, 0.0), Origin())
    msg = mavlink.MAVLink_follow_target_message(
        0, 0, round(lat * 1e7), round(lon * 1e7), 500.0, [2.0, 0.0, 0.0], [0.0] * 3,
        [1.0, 0.0, 0.0, 0.0], [0.0] * 3, [0.0] * 3, 0,
    )  # fmt: skip
    sp = from_follow_target(msg, _here(), Follow(height_m=8.0, distance_m=8.0, angle_deg=180.0))
    # heading north at 2 m/s: 8 m south of it, 8 m above home, moving with it, facing north
    assert sp is not None and sp.position_enu_m == pytest.approx((40.0, 22.0, 8.0), abs=0.05)
    assert sp.velocity_enu_m_s == pytest.approx((0.0, 2.0, 0.0))
    assert sp.yaw_deg == pytest.approx(90.0, abs=0.1)
    right = from_follow_target(msg, _here(), Follow(height_m=8.0, distance_m=5.0, angle_deg=90.0))
    assert right is not None and right.position_enu_m == pytest.approx((45.0, 30.0, 8.0), abs=0.05)
