"""MAVLink flight commands (COMMAND_LONG / COMMAND_INT, SET_MODE) → bus commands, and the
autopilot's reply → MAV_RESULT. Pure: the gateway supplies what it knows of the vehicle.

Takeoff altitude semantics differ between clients (checked on the wire): QGC sends param7 as
AMSL with NaN lat/lon, MAVSDK sends NaN (meaning MIS_TAKEOFF_ALT), MAVProxy sends a relative
altitude with lat/lon 0. COMMAND_INT carries its frame, which settles it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import Vec3, enu_yaw_deg_of_heading, geodetic_to_enu
from gcs_bridge.mission import bus_index_of_seq
from gcs_bridge.modes import flight_mode_for
from swarmbus.messages import (
    Arm,
    Command,
    CommandReply,
    Disarm,
    FlightMode,
    Goto,
    Hold,
    Land,
    MissionStart,
    Orbit,
    OrbitYaw,
    RejectCode,
    ReturnToLaunch,
    SetMode,
    Takeoff,
)
from swarmbus.scenario import Origin

ACCEPTED = int(mavlink.MAV_RESULT_ACCEPTED)
TEMPORARILY_REJECTED = int(mavlink.MAV_RESULT_TEMPORARILY_REJECTED)
DENIED = int(mavlink.MAV_RESULT_DENIED)
UNSUPPORTED = int(mavlink.MAV_RESULT_UNSUPPORTED)
FAILED = int(mavlink.MAV_RESULT_FAILED)

FORCE_DISARM_MAGIC = 21196
INT32_MAX = 2**31 - 1

_RESULT_OF_CODE = {
    RejectCode.DENIED: TEMPORARILY_REJECTED,
    RejectCode.INVALID: DENIED,
    RejectCode.UNSUPPORTED: UNSUPPORTED,
    RejectCode.FAILED: FAILED,
    RejectCode.NONE: FAILED,  # rejected without a code: still a failure, never "accepted"
}

_GLOBAL = {int(mavlink.MAV_FRAME_GLOBAL), int(mavlink.MAV_FRAME_GLOBAL_INT)}
_RELATIVE = {
    int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT),
    int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT),
}


@dataclass(frozen=True)
class CommandRequest:
    """A COMMAND_LONG or COMMAND_INT, normalised: x/y in degrees (NaN when absent)."""

    command: int
    param1: float = math.nan
    param2: float = math.nan
    param3: float = math.nan
    param4: float = math.nan
    x: float = math.nan
    y: float = math.nan
    z: float = math.nan
    frame: int | None = None  # None: COMMAND_LONG (global positions are AMSL)

    @staticmethod
    def from_long(msg: Any) -> CommandRequest:
        p = [float(getattr(msg, f"param{i}")) for i in range(1, 8)]
        return CommandRequest(int(msg.command), p[0], p[1], p[2], p[3], x=p[4], y=p[5], z=p[6])

    @staticmethod
    def from_int(msg: Any) -> CommandRequest:
        p = [float(getattr(msg, f"param{i}")) for i in range(1, 5)]
        x, y = int(msg.x), int(msg.y)
        return CommandRequest(
            int(msg.command),
            p[0],
            p[1],
            p[2],
            p[3],
            x=math.nan if x == INT32_MAX else x * 1e-7,
            y=math.nan if y == INT32_MAX else y * 1e-7,
            z=float(msg.z),
            frame=int(msg.frame),
        )


@dataclass(frozen=True)
class Facts:
    """What the gateway knows of the vehicle a command is for."""

    origin: Origin
    home_amsl_m: float | None
    home_enu: Vec3 | None
    position_enu: Vec3 | None
    landed: bool
    takeoff_altitude_m: float  # MIS_TAKEOFF_ALT
    mission_seqs: list[int]
    cruise_m_s: float = 0.0  # MPC_XY_CRUISE; a fixed wing: 0 (the autopilot flies FW_AIRSPD_TRIM)


@dataclass(frozen=True)
class Translation:
    """Either a bus command to send, or an immediate MAV_RESULT (with the reason)."""

    bus: Command | None = None
    result: int = ACCEPTED
    reason: str = ""


def refuse(result: int, reason: str) -> Translation:
    return Translation(None, result, reason)


def result_of_reply(reply: CommandReply) -> int:
    return ACCEPTED if reply.accepted else _RESULT_OF_CODE.get(reply.code, FAILED)


def _finite(v: float) -> bool:
    return math.isfinite(v)


def _arm(req: CommandRequest, facts: Facts) -> Translation:
    if req.param1 == 1.0:
        return Translation(Arm())
    if req.param1 == 0.0:
        force = req.param2 == FORCE_DISARM_MAGIC
        if not facts.landed and not force:
            return refuse(TEMPORARILY_REJECTED, "disarm in the air needs param2 = 21196")
        return Translation(Disarm(force=force))
    return refuse(DENIED, f"param1 must be 0 or 1, got {req.param1}")


def _takeoff(req: CommandRequest, facts: Facts) -> Translation:
    if facts.home_amsl_m is None:
        return refuse(TEMPORARILY_REJECTED, "no home position yet")
    z = req.z
    if math.isnan(z):  # "absent" (MAVSDK): MIS_TAKEOFF_ALT
        altitude = facts.takeoff_altitude_m
    elif not _finite(z):
        return refuse(DENIED, f"takeoff altitude {z} is not usable")
    elif req.frame in _RELATIVE:
        altitude = z
    elif req.frame in _GLOBAL:
        altitude = z - facts.home_amsl_m
    elif req.x == 0.0 and req.y == 0.0:
        altitude = z  # MAVProxy: lat/lon 0 and a relative altitude
    else:
        altitude = z - facts.home_amsl_m  # QGC: AMSL
    if not 0.0 < altitude <= 10000.0:
        return refuse(DENIED, f"takeoff altitude {altitude:.1f} m above home is not usable")
    return Translation(Takeoff(altitude_m=altitude))


def _place(req: CommandRequest, facts: Facts) -> Vec3 | Translation:
    """ENU of a command's lat/lon/alt; an absent (NaN) value keeps the vehicle's own."""
    if facts.position_enu is None or facts.home_amsl_m is None:
        return refuse(TEMPORARILY_REJECTED, "no position yet")
    here = facts.position_enu
    if _finite(req.x) and _finite(req.y):
        if not (-90.0 <= req.x <= 90.0 and -180.0 <= req.y <= 180.0):
            return refuse(DENIED, f"lat/lon {req.x}, {req.y} out of range")
        e, n, _ = geodetic_to_enu(req.x, req.y, facts.origin.alt_m, facts.origin)
    else:
        e, n = here[0], here[1]
    if _finite(req.z):
        amsl = req.z + facts.home_amsl_m if req.frame in _RELATIVE else req.z
        up = amsl - facts.origin.alt_m
    else:
        up = here[2]
    if abs(e) > 1e7 or abs(n) > 1e7 or abs(up) > 1e5:
        return refuse(DENIED, "target out of range")
    return (e, n, up)


ORBIT_DEFAULT_RADIUS_M = 10.0
ORBIT_DEFAULT_SPEED_M_S = 1.0


def _orbit(req: CommandRequest, facts: Facts) -> Translation:
    """DO_ORBIT (multicopters, as PX4): param1 radius (< 0: counter-clockwise), param2
    tangential speed (its sign also turns the direction), param3 yaw behaviour, x/y/z the
    centre (NaN: here; the altitude AMSL). Orbits go on until another mode is chosen (param4,
    the number of turns, is not counted)."""
    if any(math.isinf(v) for v in (req.param1, req.param2, req.x, req.y, req.z)):
        return refuse(DENIED, "orbit parameters are not finite")
    radius = req.param1 if _finite(req.param1) and req.param1 != 0.0 else ORBIT_DEFAULT_RADIUS_M
    speed = req.param2 if _finite(req.param2) and req.param2 != 0.0 else ORBIT_DEFAULT_SPEED_M_S
    if not 0.0 < abs(radius) <= 1000.0 or abs(speed) > 50.0:
        return refuse(DENIED, f"orbit radius {radius} m / speed {speed} m/s out of range")
    if radius < 0.0:
        speed = -speed
    behaviour = int(req.param3) if _finite(req.param3) else int(OrbitYaw.CENTRE)
    yaw = OrbitYaw(behaviour) if behaviour in OrbitYaw.__members__.values() else OrbitYaw.CENTRE
    # PX4 reads the centre's altitude as AMSL whatever the frame (MAVSDK sends AMSL in a
    # COMMAND_INT whose frame says relative)
    place = _place(dataclasses.replace(req, frame=None), facts)
    if isinstance(place, Translation):
        return place
    return Translation(Orbit(center_enu_m=place, radius_m=abs(radius), speed_m_s=speed, yaw=yaw))


def _reposition(req: CommandRequest, facts: Facts) -> Translation:
    """DO_REPOSITION: go to lat/lon/alt; absent (NaN) values keep the current ones; none →
    hold. An infinite value is garbage, never "absent"."""
    if any(math.isinf(v) for v in (req.x, req.y, req.z)):
        return refuse(DENIED, "reposition target is not finite")
    if not (_finite(req.x) or _finite(req.y) or _finite(req.z)):
        return Translation(Hold())
    place = _place(req, facts)
    if isinstance(place, Translation):
        return place
    e, n, up = place
    yaw = enu_yaw_deg_of_heading(req.param4) if _finite(req.param4) else None
    speed = req.param1 if _finite(req.param1) and 0.0 < req.param1 <= 100.0 else facts.cruise_m_s
    return Translation(Goto(position_enu_m=(e, n, up), yaw_deg=yaw, speed_m_s=speed))


def mode_command(mode: FlightMode, facts: Facts) -> Command:
    """The bus command that puts the vehicle in ``mode``."""
    if mode == FlightMode.TAKEOFF:
        return Takeoff(altitude_m=facts.takeoff_altitude_m)
    if mode == FlightMode.HOLD:
        return Hold()
    if mode == FlightMode.LAND:
        return Land()
    if mode == FlightMode.RTL:
        return ReturnToLaunch()
    return SetMode(mode=mode)


def translate_mode(base_mode: float, main: float, sub: float, facts: Facts) -> Translation:
    """DO_SET_MODE / SET_MODE: only PX4 custom modes are understood."""
    if not (_finite(base_mode) and _finite(main) and _finite(sub)):
        return refuse(DENIED, "mode parameters must be finite")
    if not int(base_mode) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return refuse(DENIED, "only custom (PX4) modes are supported")
    mode = flight_mode_for(int(main), int(sub))
    if mode is None:
        return refuse(DENIED, f"PX4 mode {int(main)}/{int(sub)} is not available (no RC)")
    return Translation(mode_command(mode, facts))


def _set_mode(req: CommandRequest, facts: Facts) -> Translation:
    return translate_mode(req.param1, req.param2, req.param3, facts)


def _mission_start(req: CommandRequest, facts: Facts) -> Translation:
    first = int(req.param1) if _finite(req.param1) and req.param1 >= 0 else 0
    return Translation(MissionStart(start_index=bus_index_of_seq(facts.mission_seqs, first)))


def _pause_continue(req: CommandRequest, facts: Facts) -> Translation:
    if req.param1 == 0.0:
        return Translation(Hold())
    if req.param1 == 1.0:
        return Translation(SetMode(mode=FlightMode.MISSION))
    return refuse(DENIED, "param1 must be 0 (pause) or 1 (continue)")


FLIGHT_COMMANDS: dict[int, Callable[[CommandRequest, Facts], Translation]] = {
    int(mavlink.MAV_CMD_COMPONENT_ARM_DISARM): _arm,
    int(mavlink.MAV_CMD_NAV_TAKEOFF): _takeoff,
    int(mavlink.MAV_CMD_NAV_LAND): lambda r, f: Translation(Land()),
    int(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH): lambda r, f: Translation(ReturnToLaunch()),
    int(mavlink.MAV_CMD_NAV_LOITER_UNLIM): lambda r, f: Translation(Hold()),
    int(mavlink.MAV_CMD_MISSION_START): _mission_start,
    int(mavlink.MAV_CMD_DO_REPOSITION): _reposition,
    int(mavlink.MAV_CMD_DO_SET_MODE): _set_mode,
    int(mavlink.MAV_CMD_DO_PAUSE_CONTINUE): _pause_continue,
    int(mavlink.MAV_CMD_DO_ORBIT): _orbit,
}


def translate(req: CommandRequest, facts: Facts) -> Translation | None:
    """The bus command for a flight command; None when it is not a flight command."""
    handler = FLIGHT_COMMANDS.get(req.command)
    return handler(req, facts) if handler is not None else None
