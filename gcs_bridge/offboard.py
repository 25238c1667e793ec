"""Offboard setpoints as PX4 takes them → bus :class:`~swarmbus.messages.Setpoint`.

SET_POSITION_TARGET_LOCAL_NED: local NED is measured from the vehicle's own local origin (its
spawn point, where PX4's estimator would have started), not from the world origin. Frames:
LOCAL_NED; LOCAL_OFFSET_NED (position relative to the vehicle); BODY_NED, BODY_OFFSET_NED and
BODY_FRD (vectors turned by the vehicle's heading, positions relative to the vehicle).
With a position, velocity and acceleration are feed-forward. Yaw, else yaw rate.
SET_POSITION_TARGET_GLOBAL_INT: latitude, longitude and an altitude AMSL (GLOBAL_INT) or above
home (RELATIVE_ALT_INT; TERRAIN_ALT_INT: above the flat ground, that is, home).
SET_ATTITUDE_TARGET: an attitude (NED/FRD quaternion) or body rates (FRD), with a thrust 0–1
of the maximum collective thrust.
Unusable setpoints (NaN, absurd magnitudes, unknown frames) give None: MAVLink has no ACK here.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import Vec3, geodetic_to_enu, ned_to_enu
from swarmbus.messages import Setpoint
from swarmbus.scenario import Origin

MAX_SETPOINT_M = 1e7  # |east|, |north| of an offboard position (the bus carries ≤ 1e9)
MAX_SETPOINT_UP_M = 1e5
MAX_SETPOINT_M_S = 1e3
MAX_SETPOINT_M_S2 = 1e3
MAX_RATE_RAD_S = 100.0

IGNORE_POSITION = 0b111
IGNORE_VELOCITY = 0b111 << 3
IGNORE_ACCELERATION = 0b111 << 6
IGNORE_YAW = 1 << 10
IGNORE_YAW_RATE = 1 << 11
IGNORE_BODY_RATES = 0b111
IGNORE_THRUST = 1 << 6
IGNORE_ATTITUDE = 1 << 7

FRAME_LOCAL_NED = int(mavlink.MAV_FRAME_LOCAL_NED)
FRAME_LOCAL_OFFSET_NED = int(mavlink.MAV_FRAME_LOCAL_OFFSET_NED)
FRAME_BODY_NED = int(mavlink.MAV_FRAME_BODY_NED)
FRAME_BODY_OFFSET_NED = int(mavlink.MAV_FRAME_BODY_OFFSET_NED)
FRAME_BODY_FRD = int(mavlink.MAV_FRAME_BODY_FRD)
_BODY = {FRAME_BODY_NED, FRAME_BODY_OFFSET_NED, FRAME_BODY_FRD}
_RELATIVE_POSITION = {FRAME_LOCAL_OFFSET_NED, *_BODY}
FRAME_GLOBAL_INT = int(mavlink.MAV_FRAME_GLOBAL_INT)
FRAME_GLOBAL_RELATIVE_ALT_INT = int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
FRAME_GLOBAL_TERRAIN_ALT_INT = int(mavlink.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT)

_HALF_SQRT2 = math.sqrt(0.5)


@dataclass(frozen=True)
class Here:
    """What a setpoint is measured against: the vehicle now, its local origin, home."""

    position_enu: Vec3
    yaw_enu_rad: float
    local_origin_enu: Vec3
    home_amsl_m: float
    origin: Origin


def _within(v: Vec3, horizontal: float, vertical: float) -> bool:
    return (
        all(map(math.isfinite, v))
        and abs(v[0]) <= horizontal
        and abs(v[1]) <= horizontal
        and abs(v[2]) <= vertical
    )


def _turned(v_frd: Vec3, yaw_enu_rad: float) -> Vec3:
    """A forward-right-down vector along the vehicle's heading, in ENU."""
    f, r, d = v_frd
    c, s = math.cos(yaw_enu_rad), math.sin(yaw_enu_rad)
    return (f * c + r * s, f * s - r * c, -d)


def _vector(v_ned: Vec3, frame: int, here: Here) -> Vec3:
    return _turned(v_ned, here.yaw_enu_rad) if frame in _BODY else ned_to_enu(v_ned)


def _enu_yaw_deg(yaw_ned_rad: float) -> float:
    return (90.0 - math.degrees(yaw_ned_rad) + 180.0) % 360.0 - 180.0


def _yaw_fields(msg: Any, mask: int) -> tuple[float | None, float | None]:
    """(yaw_deg, yaw_rate_deg_s) in ENU: a yaw, else a yaw rate, else neither."""
    yaw, rate = float(msg.yaw), float(msg.yaw_rate)
    if not mask & IGNORE_YAW and math.isfinite(yaw):
        return _enu_yaw_deg(yaw), None
    if not mask & IGNORE_YAW_RATE and math.isfinite(rate) and abs(rate) <= MAX_RATE_RAD_S:
        return None, -math.degrees(rate)  # NED: clockwise; ENU: counter-clockwise
    return None, None


def _motion(msg: Any, mask: int, position: Vec3 | None, to_enu: Any) -> Setpoint | None:
    vel = (float(msg.vx), float(msg.vy), float(msg.vz))
    acc = (float(msg.afx), float(msg.afy), float(msg.afz))
    use_vel = not mask & IGNORE_VELOCITY and _within(vel, MAX_SETPOINT_M_S, MAX_SETPOINT_M_S)
    use_acc = not mask & IGNORE_ACCELERATION and _within(acc, MAX_SETPOINT_M_S2, MAX_SETPOINT_M_S2)
    if position is None and not (use_vel or use_acc):
        return None
    yaw_deg, yaw_rate_deg_s = _yaw_fields(msg, mask)
    try:
        return Setpoint(
            position_enu_m=position,
            velocity_enu_m_s=to_enu(vel) if use_vel else None,
            acceleration_enu_m_s2=to_enu(acc) if use_acc else None,
            yaw_deg=yaw_deg,
            yaw_rate_deg_s=yaw_rate_deg_s,
        )
    except (TypeError, ValueError):
        return None


def from_local_ned(msg: Any, here: Here) -> Setpoint | None:
    """SET_POSITION_TARGET_LOCAL_NED → Setpoint (None: unusable or an unknown frame)."""
    frame = int(msg.coordinate_frame)
    if frame not in (FRAME_LOCAL_NED, *_RELATIVE_POSITION):
        return None
    mask = int(msg.type_mask)
    position = None
    pos = (float(msg.x), float(msg.y), float(msg.z))
    if not mask & IGNORE_POSITION and _within(pos, MAX_SETPOINT_M, MAX_SETPOINT_UP_M):
        offset = _vector(pos, frame, here)
        base = here.position_enu if frame in _RELATIVE_POSITION else here.local_origin_enu
        position = (base[0] + offset[0], base[1] + offset[1], base[2] + offset[2])
    return _motion(msg, mask, position, lambda v: _vector(v, frame, here))


def from_global_int(msg: Any, here: Here) -> Setpoint | None:
    """SET_POSITION_TARGET_GLOBAL_INT → Setpoint."""
    frame = int(msg.coordinate_frame)
    mask = int(msg.type_mask)
    position = None
    if not mask & IGNORE_POSITION:
        lat, lon, alt = int(msg.lat_int) * 1e-7, int(msg.lon_int) * 1e-7, float(msg.alt)
        if not (abs(lat) <= 90.0 and abs(lon) <= 180.0 and math.isfinite(alt)):
            return None
        if frame == FRAME_GLOBAL_INT:
            amsl = alt
        elif frame in (FRAME_GLOBAL_RELATIVE_ALT_INT, FRAME_GLOBAL_TERRAIN_ALT_INT):
            amsl = here.home_amsl_m + alt
        else:
            return None
        enu = geodetic_to_enu(lat, lon, amsl, here.origin)
        if not _within(enu, MAX_SETPOINT_M, MAX_SETPOINT_UP_M):
            return None
        position = enu
    return _motion(msg, mask, position, ned_to_enu)


# PX4's position-mode stick scaling (MPC_VEL_MANUAL, MPC_Z_VEL_MAX_UP / _DN, MPC_MAN_Y_MAX)
STICK_XY_M_S = 10.0
STICK_UP_M_S = 3.0
STICK_DOWN_M_S = 1.5
STICK_YAW_DEG_S = 150.0
STICK_DEADZONE = 0.05


def _stick(raw: int, scale: float = 1000.0) -> float:
    v = max(-1.0, min(1.0, raw / scale))
    return 0.0 if abs(v) < STICK_DEADZONE else v


def from_manual_control(msg: Any, here: Here) -> Setpoint | None:
    """MANUAL_CONTROL as PX4's position mode reads it: x forward, y right (−1000…1000) give a
    horizontal velocity along the heading, z throttle (0…1000, 500 centred) a climb or
    descent, r a yaw rate; centred sticks hold."""
    forward, right = _stick(int(msg.x)), _stick(int(msg.y))
    throttle = _stick(int(msg.z) - 500, 500.0)
    yaw = _stick(int(msg.r))
    up = throttle * (STICK_UP_M_S if throttle > 0 else STICK_DOWN_M_S)
    horizontal = (forward * STICK_XY_M_S, right * STICK_XY_M_S, 0.0)
    east, north, _ = _turned(horizontal, here.yaw_enu_rad)
    return Setpoint(
        velocity_enu_m_s=(east, north, up),
        yaw_rate_deg_s=-yaw * STICK_YAW_DEG_S,  # stick right: clockwise
    )


@dataclass(frozen=True)
class Follow:
    """PX4's follow-me settings: height above home, distance from the target, and the angle
    from the target's heading (0 ahead, 90 right, 180 behind; FLW_TGT_HT, _DST, _FA)."""

    height_m: float
    distance_m: float
    angle_deg: float


FOLLOW_MIN_SPEED_M_S = 0.5  # below, the target's course is unknown: keep the current bearing


def from_follow_target(msg: Any, here: Here, follow: Follow) -> Setpoint | None:
    """FOLLOW_TARGET → where the follower should be, moving with the target, facing it."""
    lat, lon = int(msg.lat) * 1e-7, int(msg.lon) * 1e-7
    if not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
        return None
    tx, ty, _ = geodetic_to_enu(lat, lon, here.origin.alt_m, here.origin)
    vn, ve = float(msg.vel[0]), float(msg.vel[1])
    moving = math.isfinite(vn) and math.isfinite(ve) and math.hypot(vn, ve) >= FOLLOW_MIN_SPEED_M_S
    if moving:
        bearing = math.atan2(ve, vn) + math.radians(follow.angle_deg)  # compass, from north
        ex, ny = math.sin(bearing), math.cos(bearing)
    else:
        dx, dy = here.position_enu[0] - tx, here.position_enu[1] - ty
        norm = math.hypot(dx, dy) or 1.0
        ex, ny = dx / norm, dy / norm
    x, y = tx + follow.distance_m * ex, ty + follow.distance_m * ny
    up = here.home_amsl_m - here.origin.alt_m + follow.height_m
    yaw = math.degrees(math.atan2(ty - y, tx - x))
    velocity = (ve, vn, 0.0) if moving else None
    if not _within((x, y, up), MAX_SETPOINT_M, MAX_SETPOINT_UP_M):
        return None
    return Setpoint(position_enu_m=(x, y, up), velocity_enu_m_s=velocity, yaw_deg=yaw)


def enu_flu_of_ned_frd(
    q_wxyz: tuple[float, float, float, float],
) -> tuple[float, float, float, float]:
    """A body FRD → NED quaternion (MAVLink's w, x, y, z) as body FLU → ENU (x, y, z, w):
    q_A ⊗ q ⊗ q_B with A the NED/ENU axis swap (π about (1, 1, 0)/√2) and B the FLU/FRD flip
    (π about x); both are their own inverses."""
    w, x, y, z = q_wxyz
    # q_A ⊗ q, q_A = (x, y, z, w) = (√½, √½, 0, 0)
    a = _HALF_SQRT2
    w1 = -a * x - a * y
    x1 = a * w + a * z
    y1 = a * w - a * z
    z1 = a * y - a * x
    # (q_A ⊗ q) ⊗ q_B, q_B = (1, 0, 0, 0)
    return (w1, z1, -y1, -x1)


def from_attitude_target(msg: Any) -> Setpoint | None:
    """SET_ATTITUDE_TARGET → an attitude or body-rate Setpoint with its thrust."""
    mask = int(msg.type_mask)
    thrust = float(msg.thrust)
    if mask & IGNORE_THRUST or not (math.isfinite(thrust) and 0.0 <= thrust <= 1.0):
        return None
    try:
        if not mask & IGNORE_ATTITUDE:
            q = tuple(float(c) for c in msg.q)
            norm = math.sqrt(sum(c * c for c in q))
            if not (math.isfinite(norm) and norm > 1e-6):
                return None
            w, x, y, z = (c / norm for c in q)
            return Setpoint(attitude_xyzw=enu_flu_of_ned_frd((w, x, y, z)), thrust=thrust)
        if mask & IGNORE_BODY_RATES:
            return None  # PX4 takes all three rates or none
        p, q_, r = float(msg.body_roll_rate), float(msg.body_pitch_rate), float(msg.body_yaw_rate)
        if not _within((p, q_, r), MAX_RATE_RAD_S, MAX_RATE_RAD_S):
            return None
        return Setpoint(body_rates_rad_s=(p, -q_, -r), thrust=thrust)
    except (TypeError, ValueError):
        return None
