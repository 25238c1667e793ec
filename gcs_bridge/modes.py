"""PX4 flight-mode encoding of the autopilot's real :class:`FlightMode`, and back.

PX4 puts its mode in HEARTBEAT ``custom_mode`` as ``main_mode << 16 | sub_mode << 24``; QGC and
MAVSDK decode it that way when ``autopilot = MAV_AUTOPILOT_PX4``. There is no RC in the
simulation: MANUAL/ALTCTL/ACRO/STABILIZED requests are refused; POSCTL is flown from the
ground station's MANUAL_CONTROL sticks (PX4's joystick path).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from gcs_bridge.dialect import mavlink
from swarmbus.messages import FlightMode, VehicleStatus


class Px4Main(enum.IntEnum):
    MANUAL = 1
    ALTCTL = 2
    POSCTL = 3
    AUTO = 4
    ACRO = 5
    OFFBOARD = 6
    STABILIZED = 7


class Px4AutoSub(enum.IntEnum):
    NONE = 0
    READY = 1
    TAKEOFF = 2
    LOITER = 3
    MISSION = 4
    RTL = 5
    LAND = 6
    FOLLOW_TARGET = 8


PX4_POSCTL_SUB_ORBIT = 1  # PX4 shows its orbit as POSCTL / ORBIT


@dataclass(frozen=True)
class Px4Mode:
    main: int
    sub: int = 0

    @property
    def custom_mode(self) -> int:
        return encode_custom_mode(self.main, self.sub)


HOLD = Px4Mode(Px4Main.AUTO, Px4AutoSub.LOITER)

# Disarmed and armed-idle vehicles hold position, as PX4 does on the ground without RC.
_PX4_OF_MODE: dict[FlightMode, Px4Mode] = {
    FlightMode.DISARMED: HOLD,
    FlightMode.ARMED: HOLD,
    FlightMode.TAKEOFF: Px4Mode(Px4Main.AUTO, Px4AutoSub.TAKEOFF),
    FlightMode.HOLD: HOLD,
    FlightMode.MISSION: Px4Mode(Px4Main.AUTO, Px4AutoSub.MISSION),
    FlightMode.RTL: Px4Mode(Px4Main.AUTO, Px4AutoSub.RTL),
    FlightMode.LAND: Px4Mode(Px4Main.AUTO, Px4AutoSub.LAND),
    FlightMode.OFFBOARD: Px4Mode(Px4Main.OFFBOARD),
    FlightMode.ORBIT: Px4Mode(Px4Main.POSCTL, PX4_POSCTL_SUB_ORBIT),
    FlightMode.POSITION: Px4Mode(Px4Main.POSCTL),
    FlightMode.FOLLOW: Px4Mode(Px4Main.AUTO, Px4AutoSub.FOLLOW_TARGET),
}

_MODE_OF_AUTO_SUB: dict[int, FlightMode] = {
    Px4AutoSub.TAKEOFF: FlightMode.TAKEOFF,
    Px4AutoSub.LOITER: FlightMode.HOLD,
    Px4AutoSub.MISSION: FlightMode.MISSION,
    Px4AutoSub.RTL: FlightMode.RTL,
    Px4AutoSub.LAND: FlightMode.LAND,
    Px4AutoSub.FOLLOW_TARGET: FlightMode.FOLLOW,
}

_BASE_AUTO = (
    mavlink.MAV_MODE_FLAG_AUTO_ENABLED
    | mavlink.MAV_MODE_FLAG_GUIDED_ENABLED
    | mavlink.MAV_MODE_FLAG_STABILIZE_ENABLED
)

_MAV_TYPE_OF_ROTORS = {
    3: mavlink.MAV_TYPE_TRICOPTER,
    4: mavlink.MAV_TYPE_QUADROTOR,
    6: mavlink.MAV_TYPE_HEXAROTOR,
    8: mavlink.MAV_TYPE_OCTOROTOR,
}


def encode_custom_mode(main: int, sub: int = 0) -> int:
    return ((int(main) & 0xFF) << 16) | ((int(sub) & 0xFF) << 24)


def decode_custom_mode(custom_mode: int) -> Px4Mode:
    return Px4Mode((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)


def px4_mode_of(mode: FlightMode) -> Px4Mode:
    return _PX4_OF_MODE[mode]


def flight_mode_for(main: int, sub: int) -> FlightMode | None:
    """The autopilot mode a PX4 (main, sub) mode request asks for; None if we have none."""
    if main == Px4Main.AUTO:
        return _MODE_OF_AUTO_SUB.get(sub)
    if main == Px4Main.OFFBOARD:
        return FlightMode.OFFBOARD
    if main == Px4Main.POSCTL and sub == 0:
        return FlightMode.POSITION
    return None


def base_mode_of(status: VehicleStatus | None) -> int:
    base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    if status is None:
        return int(base)
    base |= _BASE_AUTO
    if status.armed:
        base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    return int(base)


def custom_mode_of(status: VehicleStatus | None) -> int:
    mode = status.mode if status is not None else FlightMode.DISARMED
    return px4_mode_of(mode).custom_mode


def system_status_of(status: VehicleStatus | None) -> int:
    """MAV_STATE of a vehicle: booting until its autopilot reports, then its health."""
    if status is None:
        return int(mavlink.MAV_STATE_BOOT)
    if status.crashed:
        return int(mavlink.MAV_STATE_EMERGENCY)
    if status.failsafe:
        return int(mavlink.MAV_STATE_CRITICAL)
    if status.armed:
        return int(mavlink.MAV_STATE_ACTIVE)
    return int(mavlink.MAV_STATE_STANDBY)


def mav_type_of(kind: str, rotor_count: int) -> int:
    """MAV_TYPE of a vehicle type: ``fixed_wing`` is MAV_TYPE_FIXED_WING; a multirotor's
    follows its ``rotor_count`` (quad when unusual). PX4 reports a plane's modes with the same
    main and sub modes as a multirotor's (hold is AUTO / LOITER)."""
    if kind == "fixed_wing":
        return int(mavlink.MAV_TYPE_FIXED_WING)
    return int(_MAV_TYPE_OF_ROTORS.get(rotor_count, mavlink.MAV_TYPE_QUADROTOR))
