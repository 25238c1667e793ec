"""Telemetry: what each stream says about a vehicle, and when it is due (in sim time).

The simulation runs faster than real time in lockstep, so a stream's rate is per simulated
second: a stream is due when the sim time of the vehicle's latest state has passed its next
due time. ``time_boot_ms`` is the sim time, so a client can measure rates in sim time too.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.frames import (
    Vec3,
    course_deg,
    enu_to_ned,
    euler_ned_frd,
    flu_to_frd,
    heading_deg,
)
from swarmbus.messages import (
    ConcentrationReading,
    FlightMode,
    VehicleState,
    VehicleStatus,
)

CONCENTRATION_NAME = b"conc_gm3"

ID_SYS_STATUS = int(mavlink.MAVLINK_MSG_ID_SYS_STATUS)
ID_GPS_RAW_INT = int(mavlink.MAVLINK_MSG_ID_GPS_RAW_INT)
ID_ATTITUDE = int(mavlink.MAVLINK_MSG_ID_ATTITUDE)
ID_LOCAL_POSITION_NED = int(mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)
ID_GLOBAL_POSITION_INT = int(mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT)
ID_MISSION_CURRENT = int(mavlink.MAVLINK_MSG_ID_MISSION_CURRENT)
ID_VFR_HUD = int(mavlink.MAVLINK_MSG_ID_VFR_HUD)
ID_BATTERY_STATUS = int(mavlink.MAVLINK_MSG_ID_BATTERY_STATUS)
ID_HOME_POSITION = int(mavlink.MAVLINK_MSG_ID_HOME_POSITION)
ID_EXTENDED_SYS_STATE = int(mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE)
ID_NAMED_VALUE_FLOAT = int(mavlink.MAVLINK_MSG_ID_NAMED_VALUE_FLOAT)

# Streams sent at the scenario's telemetry rate unless SET_MESSAGE_INTERVAL says otherwise.
FAST_STREAMS = (
    ID_SYS_STATUS,
    ID_GPS_RAW_INT,
    ID_GLOBAL_POSITION_INT,
    ID_LOCAL_POSITION_NED,
    ID_ATTITUDE,
    ID_VFR_HUD,
    ID_EXTENDED_SYS_STATE,
    ID_NAMED_VALUE_FLOAT,
)
# Slow streams and their fixed default rates (Hz of sim time).
SLOW_STREAMS = {ID_BATTERY_STATUS: 1.0, ID_HOME_POSITION: 0.5, ID_MISSION_CURRENT: 1.0}

SENSORS = (
    mavlink.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mavlink.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mavlink.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mavlink.MAV_SYS_STATUS_SENSOR_GPS
    | mavlink.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mavlink.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mavlink.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mavlink.MAV_SYS_STATUS_AHRS
)
PREARM = int(mavlink.MAV_SYS_STATUS_PREARM_CHECK)
UINT16_MAX = 0xFFFF
INT16_MAX = 0x7FFF


def default_rates(telemetry_hz: float) -> dict[int, float]:
    rates = dict.fromkeys(FAST_STREAMS, telemetry_hz)
    rates.update(SLOW_STREAMS)
    return rates


class StreamSchedule:
    """When each stream of one vehicle on one link is next due, in sim seconds."""

    def __init__(self, default_hz: dict[int, float]) -> None:
        self._default_hz = dict(default_hz)
        self._interval_s: dict[int, float | None] = {
            k: 1.0 / hz for k, hz in default_hz.items() if hz > 0
        }
        self._next_s: dict[int, float] = {}
        self._last_s: float | None = None
        # :meth:`wants` is false exactly while lo - 1e-6 <= t < hi - 1e-9 (kept up to date):
        self.lo = -math.inf  # the last sim time streams were due at (before it: a restart)
        self.hi = -math.inf  # the earliest next due time of an enabled stream
        self._refresh()

    def _refresh(self) -> None:
        self.lo = -math.inf if self._last_s is None else self._last_s
        hi = math.inf
        for msg_id, interval in self._interval_s.items():
            if interval is not None:
                hi = min(hi, self._next_s.get(msg_id, -math.inf))
        self.hi = hi

    def knows(self, msg_id: int) -> bool:
        return msg_id in self._default_hz

    def set_interval_us(self, msg_id: int, interval_us: float) -> bool:
        """SET_MESSAGE_INTERVAL: -1 off, 0 default, > 0 that interval. False if unknown."""
        if msg_id not in self._default_hz or not math.isfinite(interval_us):
            return False
        if interval_us < 0:
            self._interval_s[msg_id] = None
        elif interval_us == 0:
            hz = self._default_hz[msg_id]
            self._interval_s[msg_id] = 1.0 / hz if hz > 0 else None
        else:
            self._interval_s[msg_id] = max(interval_us * 1e-6, 1e-3)
        self._next_s.pop(msg_id, None)
        self._refresh()
        return True

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL's answer: -1 off, 0 unknown stream, else the interval."""
        if msg_id not in self._default_hz:
            return 0
        interval = self._interval_s.get(msg_id)
        return -1 if interval is None else round(interval * 1e6)

    def wants(self, sim_time_s: float) -> bool:
        """Whether :meth:`due` would return any stream at ``sim_time_s`` (changes nothing)."""
        if self._last_s is not None and sim_time_s < self._last_s - 1e-6:
            return True
        for msg_id, interval in self._interval_s.items():
            if interval is not None:
                next_s = self._next_s.get(msg_id)
                if next_s is None or sim_time_s >= next_s - 1e-9:
                    return True
        return False

    def due(self, sim_time_s: float) -> list[int]:
        """Streams due at ``sim_time_s``; each one's next due time moves one interval on."""
        if self._last_s is not None and sim_time_s < self._last_s - 1e-6:
            self._next_s.clear()  # the simulation restarted
        self._last_s = sim_time_s
        out: list[int] = []
        for msg_id, interval in self._interval_s.items():
            if interval is None:
                continue
            next_s = self._next_s.get(msg_id)
            if next_s is None or sim_time_s >= next_s - 1e-9:
                out.append(msg_id)
                nxt = sim_time_s + interval if next_s is None else next_s + interval
                if nxt <= sim_time_s:  # fell behind: skip, never burst
                    nxt = sim_time_s + interval
                self._next_s[msg_id] = nxt
        self._refresh()
        return out


# ----------------------------------------------------------------------------- builders
@dataclass(frozen=True)
class View:
    """What the gateway knows of one vehicle when it builds a message."""

    state: VehicleState | None
    status: VehicleStatus | None
    reading: ConcentrationReading | None
    home_geodetic: Vec3 | None  # lat, lon, alt AMSL
    home_enu: Vec3 | None
    wind_enu: Vec3
    local_origin_enu: Vec3 = (0.0, 0.0, 0.0)  # where local NED starts: the spawn, as PX4


def _needs_state(build: Callable[[View, VehicleState], Msg]) -> Callable[[View], Msg | None]:
    """``build`` for a vehicle whose state is known; None before its first state."""

    def builder(view: View) -> Msg | None:
        return None if view.state is None else build(view, view.state)

    return builder


def _local(view: View, enu: Vec3) -> Vec3:
    o = view.local_origin_enu
    return enu_to_ned((enu[0] - o[0], enu[1] - o[1], enu[2] - o[2]))


def boot_ms(sim_time_s: float) -> int:
    return int(sim_time_s * 1000.0) & 0xFFFFFFFF


def _clamp_int(v: float, lo: int, hi: int) -> int:
    if not math.isfinite(v):
        return 0
    return max(lo, min(hi, round(v)))


def _e7(deg: float) -> int:
    return round(deg * 1e7)


def sys_status(view: View) -> Msg:
    health = SENSORS
    st, status = view.state, view.status
    if st is not None and not st.motors_enabled:
        health &= ~mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    healthy = status is not None and not status.crashed and status.health == "ok"
    if not healthy:
        health &= ~(mavlink.MAV_SYS_STATUS_AHRS | mavlink.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS)
    if healthy and st is not None:
        health |= PREARM
    present = SENSORS | PREARM
    return mavlink.MAVLink_sys_status_message(
        present, present, int(health), 0, UINT16_MAX, -1, -1, 0, 0, 0, 0, 0, 0
    )


def gps_raw_int(view: View, st: VehicleState) -> Msg:
    v = st.velocity_enu_m_s
    ground = math.hypot(v[0], v[1])
    cog = _clamp_int(course_deg(v) * 100.0, 0, 35999) if ground > 0.1 else UINT16_MAX
    return mavlink.MAVLink_gps_raw_int_message(
        int(st.sim_time_s * 1e6),
        mavlink.GPS_FIX_TYPE_3D_FIX,
        _e7(st.lat_deg),
        _e7(st.lon_deg),
        round(st.alt_m * 1000.0),
        80,
        120,
        _clamp_int(ground * 100.0, 0, UINT16_MAX - 1),
        cog,
        14,
    )


def global_position_int(view: View, st: VehicleState) -> Msg:
    vn, ve, vd = enu_to_ned(st.velocity_enu_m_s)
    _, _, yaw = euler_ned_frd(st.attitude_xyzw)
    home_alt = view.home_geodetic[2] if view.home_geodetic is not None else st.alt_m
    return mavlink.MAVLink_global_position_int_message(
        boot_ms(st.sim_time_s),
        _e7(st.lat_deg),
        _e7(st.lon_deg),
        round(st.alt_m * 1000.0),
        round((st.alt_m - home_alt) * 1000.0),
        _clamp_int(vn * 100.0, -32767, 32767),
        _clamp_int(ve * 100.0, -32767, 32767),
        _clamp_int(vd * 100.0, -32767, 32767),
        _clamp_int(heading_deg(yaw) * 100.0, 0, 35999),
    )


def local_position_ned(view: View, st: VehicleState) -> Msg:
    x, y, z = _local(view, st.position_enu_m)
    vx, vy, vz = enu_to_ned(st.velocity_enu_m_s)
    return mavlink.MAVLink_local_position_ned_message(boot_ms(st.sim_time_s), x, y, z, vx, vy, vz)


def attitude(view: View, st: VehicleState) -> Msg:
    roll, pitch, yaw = euler_ned_frd(st.attitude_xyzw)
    p, q, r = flu_to_frd(st.body_rates_rad_s)
    return mavlink.MAVLink_attitude_message(boot_ms(st.sim_time_s), roll, pitch, yaw, p, q, r)


def vfr_hud(view: View, st: VehicleState) -> Msg:
    v = st.velocity_enu_m_s
    w = view.wind_enu
    air = math.sqrt((v[0] - w[0]) ** 2 + (v[1] - w[1]) ** 2 + (v[2] - w[2]) ** 2)
    _, _, yaw = euler_ned_frd(st.attitude_xyzw)
    # No throttle on the bus (actuators are the lockstep's, not telemetry): reported as 0.
    return mavlink.MAVLink_vfr_hud_message(
        air, math.hypot(v[0], v[1]), int(heading_deg(yaw)) % 360, 0, st.alt_m, v[2]
    )


def landed_state_of(status: VehicleStatus | None) -> int:
    if status is None:
        return int(mavlink.MAV_LANDED_STATE_UNDEFINED)
    if status.landed:
        if status.armed and status.mode == FlightMode.TAKEOFF:
            return int(mavlink.MAV_LANDED_STATE_TAKEOFF)
        return int(mavlink.MAV_LANDED_STATE_ON_GROUND)
    if status.mode == FlightMode.TAKEOFF:
        return int(mavlink.MAV_LANDED_STATE_TAKEOFF)
    if status.mode == FlightMode.LAND:
        return int(mavlink.MAV_LANDED_STATE_LANDING)
    return int(mavlink.MAV_LANDED_STATE_IN_AIR)


def extended_sys_state(view: View) -> Msg:
    return mavlink.MAVLink_extended_sys_state_message(
        mavlink.MAV_VTOL_STATE_UNDEFINED, landed_state_of(view.status)
    )


def home_position(view: View) -> Msg | None:
    if view.home_geodetic is None or view.home_enu is None:
        return None
    lat, lon, alt = view.home_geodetic
    x, y, z = _local(view, view.home_enu)
    t_us = int(view.state.sim_time_s * 1e6) if view.state is not None else 0
    return mavlink.MAVLink_home_position_message(
        _e7(lat), _e7(lon), round(alt * 1000.0), x, y, z, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, t_us
    )


def battery_status(view: View) -> Msg:
    """There is no battery model: every field says "not known" as MAVLink defines it."""
    return mavlink.MAVLink_battery_status_message(
        0,
        mavlink.MAV_BATTERY_FUNCTION_ALL,
        mavlink.MAV_BATTERY_TYPE_LIPO,
        INT16_MAX,
        [UINT16_MAX] * 10,
        -1,
        -1,
        -1,
        -1,
    )


def named_value_float(view: View) -> Msg | None:
    r = view.reading
    if r is None:
        return None
    value = r.reported_g_m3 if r.available and r.reported_g_m3 is not None else math.nan
    return mavlink.MAVLink_named_value_float_message(
        boot_ms(r.sim_time_s), CONCENTRATION_NAME, value
    )


BUILDERS: dict[int, Callable[[View], Msg | None]] = {
    ID_SYS_STATUS: sys_status,
    ID_GPS_RAW_INT: _needs_state(gps_raw_int),
    ID_GLOBAL_POSITION_INT: _needs_state(global_position_int),
    ID_LOCAL_POSITION_NED: _needs_state(local_position_ned),
    ID_ATTITUDE: _needs_state(attitude),
    ID_VFR_HUD: _needs_state(vfr_hud),
    ID_EXTENDED_SYS_STATE: extended_sys_state,
    ID_HOME_POSITION: home_position,
    ID_BATTERY_STATUS: battery_status,
    ID_NAMED_VALUE_FLOAT: named_value_float,
}
