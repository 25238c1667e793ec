"""The MAVLink mission protocol, per vehicle: item conversion and the upload state machine.

Upload: GCS MISSION_COUNT → vehicle MISSION_REQUEST_INT(seq) → GCS MISSION_ITEM_INT(seq) … →
vehicle MISSION_ACK. The vehicle drives the transfer (re-requests on timeout). Download is
stateless: the vehicle answers each MISSION_REQUEST(_INT) from a snapshot.

A MAVLink mission can hold items our autopilot has no item for (DO_CHANGE_SPEED); they fold
into the following navigation items, and :class:`Converted` keeps the MAVLink seq of every
bus item so that MISSION_CURRENT / MISSION_ITEM_REACHED speak in MAVLink seqs.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import enu_to_geodetic, geodetic_to_enu
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import MAX_MISSION_ITEMS, MissionCommand, MissionFrame, MissionItem
from swarmbus.scenario import Origin


class Result(enum.IntEnum):
    """MAV_MISSION_RESULT."""

    ACCEPTED = mavlink.MAV_MISSION_ACCEPTED
    ERROR = mavlink.MAV_MISSION_ERROR
    UNSUPPORTED_FRAME = mavlink.MAV_MISSION_UNSUPPORTED_FRAME
    UNSUPPORTED = mavlink.MAV_MISSION_UNSUPPORTED
    NO_SPACE = mavlink.MAV_MISSION_NO_SPACE
    INVALID = mavlink.MAV_MISSION_INVALID
    INVALID_PARAM1 = mavlink.MAV_MISSION_INVALID_PARAM1
    INVALID_PARAM2 = mavlink.MAV_MISSION_INVALID_PARAM2
    INVALID_PARAM4 = mavlink.MAV_MISSION_INVALID_PARAM4
    INVALID_PARAM5_X = mavlink.MAV_MISSION_INVALID_PARAM5_X
    INVALID_PARAM6_Y = mavlink.MAV_MISSION_INVALID_PARAM6_Y
    INVALID_PARAM7 = mavlink.MAV_MISSION_INVALID_PARAM7
    INVALID_SEQUENCE = mavlink.MAV_MISSION_INVALID_SEQUENCE
    DENIED = mavlink.MAV_MISSION_DENIED
    OPERATION_CANCELLED = mavlink.MAV_MISSION_OPERATION_CANCELLED


MISSION_TYPE_MISSION = int(mavlink.MAV_MISSION_TYPE_MISSION)
MISSION_TYPE_ALL = int(mavlink.MAV_MISSION_TYPE_ALL)
MISSION_TYPE_FENCE = int(mavlink.MAV_MISSION_TYPE_FENCE)
MISSION_TYPE_RALLY = int(mavlink.MAV_MISSION_TYPE_RALLY)
PLAN_TYPES = (MISSION_TYPE_MISSION, MISSION_TYPE_FENCE, MISSION_TYPE_RALLY)

CMD_WAYPOINT = int(mavlink.MAV_CMD_NAV_WAYPOINT)
CMD_LOITER_TIME = int(mavlink.MAV_CMD_NAV_LOITER_TIME)
CMD_LOITER_TO_ALT = int(mavlink.MAV_CMD_NAV_LOITER_TO_ALT)
CMD_RTL = int(mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH)
CMD_LAND = int(mavlink.MAV_CMD_NAV_LAND)
CMD_TAKEOFF = int(mavlink.MAV_CMD_NAV_TAKEOFF)
CMD_CHANGE_SPEED = int(mavlink.MAV_CMD_DO_CHANGE_SPEED)
CMD_LAND_START = int(mavlink.MAV_CMD_DO_LAND_START)

FRAME_GLOBAL = int(mavlink.MAV_FRAME_GLOBAL)
FRAME_GLOBAL_INT = int(mavlink.MAV_FRAME_GLOBAL_INT)
FRAME_RELATIVE = int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT)
FRAME_RELATIVE_INT = int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
FRAME_MISSION = int(mavlink.MAV_FRAME_MISSION)
_GLOBAL_FRAMES = {FRAME_GLOBAL, FRAME_GLOBAL_INT}
_RELATIVE_FRAMES = {FRAME_RELATIVE, FRAME_RELATIVE_INT}

DEFAULT_ACCEPTANCE_M = 1.0


@dataclass(frozen=True)
class WireItem:
    """A MISSION_ITEM_INT's content (x, y in degE7), as the GCS sent it."""

    seq: int
    frame: int
    command: int
    param1: float = 0.0
    param2: float = 0.0
    param3: float = 0.0
    param4: float = 0.0
    x: int = 0
    y: int = 0
    z: float = 0.0
    autocontinue: int = 1
    mission_type: int = MISSION_TYPE_MISSION


@dataclass(frozen=True)
class Place:
    """Where "here" is for items that give no position: the vehicle's home."""

    lat_deg: float
    lon_deg: float
    alt_amsl_m: float
    origin: Origin


@dataclass(frozen=True)
class Converted:
    items: list[MissionItem]
    seqs: list[int]  # MAVLink seq of each bus item
    wire: list[WireItem]  # what the GCS sent (returned verbatim on download)


class MissionError(PlumeswarmError, ValueError):
    def __init__(self, result: Result, seq: int, reason: str) -> None:
        self.result = result
        self.seq = seq
        self.reason = reason
        super().__init__(f"item {seq}: {reason}")


def _finite(v: float) -> bool:
    return isinstance(v, float | int) and math.isfinite(v)


def _position(w: WireItem, here: Place, needs_position: bool) -> tuple[float, float, float]:
    """ENU position of an item (lat/lon 0 or absent means "here" for takeoff and land)."""
    lat = w.x * 1e-7
    lon = w.y * 1e-7
    if w.frame in _RELATIVE_FRAMES:
        alt = here.alt_amsl_m + w.z
    elif w.frame in _GLOBAL_FRAMES:
        alt = w.z
    else:
        raise MissionError(Result.UNSUPPORTED_FRAME, w.seq, f"frame {w.frame} not supported")
    if w.x == 0 and w.y == 0 and not needs_position:
        lat, lon = here.lat_deg, here.lon_deg
    if not -90.0 <= lat <= 90.0:
        raise MissionError(Result.INVALID_PARAM5_X, w.seq, f"latitude {lat} out of range")
    if not -180.0 <= lon <= 180.0:
        raise MissionError(Result.INVALID_PARAM6_Y, w.seq, f"longitude {lon} out of range")
    if not _finite(alt) or abs(alt) > 1e5:
        raise MissionError(Result.INVALID_PARAM7, w.seq, f"altitude {w.z} not usable")
    return geodetic_to_enu(lat, lon, alt, here.origin)


def item_position_enu(w: WireItem, here: Place) -> tuple[float, float, float]:
    """ENU position of an item that must give one (rally points)."""
    return _position(w, here, needs_position=True)


def _yaw(param4: float) -> float | None:
    """PX4 mission yaw (compass deg, NaN = keep) → our ENU yaw (deg)."""
    if not _finite(param4):
        return None
    return (90.0 - param4 + 180.0) % 360.0 - 180.0


def convert_upload(wire: list[WireItem], here: Place, cruise_m_s: float = 0.0) -> Converted:
    """Bus mission items of a complete MAVLink upload, or :class:`MissionError`.

    Items fly at ``cruise_m_s`` (MPC_XY_CRUISE; 0: the autopilot's default) until a
    DO_CHANGE_SPEED says otherwise.
    """
    items: list[MissionItem] = []
    seqs: list[int] = []
    speed = cruise_m_s
    for w in wire:
        if w.command == CMD_CHANGE_SPEED:
            speed = _changed_speed(w, speed)
            continue
        if w.command == CMD_LAND_START:  # a marker where the landing begins: nothing to fly
            continue
        if w.command == CMD_RTL:
            items.append(_rtl_item(here))
        elif w.command in (CMD_WAYPOINT, CMD_LOITER_TIME, CMD_LOITER_TO_ALT, CMD_TAKEOFF, CMD_LAND):
            items.append(_navigation_item(w, here, speed))
        else:
            raise MissionError(Result.UNSUPPORTED, w.seq, f"command {w.command} not supported")
        seqs.append(w.seq)
    return Converted(items=items, seqs=seqs, wire=list(wire))


def _changed_speed(w: WireItem, speed: float) -> float:
    """The speed after a DO_CHANGE_SPEED (0 or less keeps ``speed``)."""
    if _finite(w.param2) and w.param2 > 0:
        return min(float(w.param2), 100.0)
    if not _finite(w.param2):
        raise MissionError(Result.INVALID_PARAM2, w.seq, "speed is not finite")
    return speed


def _rtl_item(here: Place) -> MissionItem:
    home = geodetic_to_enu(here.lat_deg, here.lon_deg, here.alt_amsl_m, here.origin)
    return MissionItem(command=MissionCommand.RTL, x=home[0], y=home[1], z=home[2])


def _hold_and_radius(w: WireItem) -> tuple[float, float]:
    """A waypoint's or loiter's hold time (param1) and a waypoint's acceptance radius (param2)."""
    hold = 0.0
    radius = DEFAULT_ACCEPTANCE_M
    if w.command in (CMD_WAYPOINT, CMD_LOITER_TIME):
        if not _finite(w.param1) or not 0.0 <= w.param1 <= 3600.0:
            raise MissionError(Result.INVALID_PARAM1, w.seq, f"hold time {w.param1}")
        hold = float(w.param1)
    if w.command == CMD_WAYPOINT and math.isinf(w.param2):
        raise MissionError(Result.INVALID_PARAM2, w.seq, f"acceptance {w.param2}")
    if w.command == CMD_WAYPOINT and _finite(w.param2) and w.param2 > 0:
        if w.param2 > 1000.0:
            raise MissionError(Result.INVALID_PARAM2, w.seq, f"acceptance {w.param2}")
        radius = float(w.param2)
    return hold, radius


def _navigation_item(w: WireItem, here: Place, speed: float) -> MissionItem:
    """A waypoint, loiter, takeoff or land item. A loiter to altitude (QGC's final approach of
    a fixed-wing landing pattern) is a waypoint at its point and altitude: the vehicle reaches
    the altitude on its way there, it does not circle."""
    positioned = (CMD_WAYPOINT, CMD_LOITER_TIME, CMD_LOITER_TO_ALT)
    x, y, z = _position(w, here, needs_position=w.command in positioned)
    hold, radius = _hold_and_radius(w)
    command = {
        CMD_TAKEOFF: MissionCommand.TAKEOFF,
        CMD_LAND: MissionCommand.LAND,
    }.get(w.command, MissionCommand.WAYPOINT)
    return MissionItem(
        command=command,
        x=x,
        y=y,
        z=z,
        frame=MissionFrame.ENU,
        acceptance_radius_m=radius,
        hold_s=hold,
        speed_m_s=speed,
        yaw_deg=_yaw(w.param4),
    )


def wire_of_items(items: list[MissionItem], here: Place) -> list[WireItem]:
    """MAVLink items (relative-altitude frame, as QGC plans them) of an autopilot mission."""
    out: list[WireItem] = []
    for i, item in enumerate(items):
        if item.frame == MissionFrame.GLOBAL:
            lat, lon, alt = item.x, item.y, item.z
        else:
            lat, lon, alt = enu_to_geodetic((item.x, item.y, item.z), here.origin)
        command = {
            MissionCommand.TAKEOFF: CMD_TAKEOFF,
            MissionCommand.LAND: CMD_LAND,
            MissionCommand.RTL: CMD_RTL,
        }.get(item.command, CMD_WAYPOINT)
        yaw = math.nan if item.yaw_deg is None else (90.0 - item.yaw_deg) % 360.0
        if command == CMD_RTL:
            out.append(WireItem(seq=i, frame=FRAME_MISSION, command=command))
            continue
        out.append(
            WireItem(
                seq=i,
                frame=FRAME_RELATIVE_INT,
                command=command,
                param1=item.hold_s if command == CMD_WAYPOINT else 0.0,
                param2=item.acceptance_radius_m if command == CMD_WAYPOINT else 0.0,
                param4=yaw,
                x=round(lat * 1e7),
                y=round(lon * 1e7),
                z=alt - here.alt_amsl_m,
            )
        )
    return out


# ----------------------------------------------------------------------------- upload
@dataclass(frozen=True)
class Peer:
    """Who is on the other end of a transfer: a link, an address, and a MAVLink identity."""

    link: str
    addr: tuple[str, int]
    system: int
    component: int


@dataclass(frozen=True)
class Request:
    peer: Peer
    seq: int
    mission_type: int


@dataclass(frozen=True)
class Ack:
    peer: Peer
    result: Result
    mission_type: int


@dataclass(frozen=True)
class Complete:
    """All items received: convert them and hand them to the autopilot, then ACK."""

    peer: Peer
    items: list[WireItem]
    mission_type: int


Action = Request | Ack | Complete


@dataclass
class _Transfer:
    peer: Peer
    mission_type: int
    count: int
    items: list[WireItem] = field(default_factory=list)
    last_activity_s: float = 0.0
    retries: int = 0

    @property
    def next_seq(self) -> int:
        return len(self.items)


class Uploader:
    """One vehicle's mission-upload state machine (wall-clock timeouts: it talks to people)."""

    def __init__(self, item_timeout_s: float = 1.0, max_retries: int = 5) -> None:
        self.item_timeout_s = item_timeout_s
        self.max_retries = max_retries
        self._transfer: _Transfer | None = None

    @property
    def active(self) -> bool:
        return self._transfer is not None

    def on_count(self, peer: Peer, count: int, mission_type: int, now_s: float) -> list[Action]:
        if mission_type not in PLAN_TYPES:
            return [Ack(peer, Result.UNSUPPORTED, mission_type)]
        t = self._transfer
        if t is not None and t.peer != peer:
            return [Ack(peer, Result.DENIED, mission_type)]  # another GCS is uploading
        if count > MAX_MISSION_ITEMS:
            self._transfer = None
            return [Ack(peer, Result.NO_SPACE, mission_type)]
        if count == 0:
            self._transfer = None
            return [Complete(peer, [], mission_type)]
        self._transfer = _Transfer(peer, mission_type, count, last_activity_s=now_s)
        return [Request(peer, 0, mission_type)]

    def on_item(self, peer: Peer, item: WireItem, now_s: float) -> list[Action]:
        t = self._transfer
        if t is None:
            return []  # no transfer: a late duplicate, or a client that never sent a count
        if t.peer != peer:
            return [Ack(peer, Result.DENIED, item.mission_type)]
        if item.mission_type != t.mission_type:
            self._transfer = None  # the upload is broken: the client starts again
            return [Ack(peer, Result.INVALID, t.mission_type)]
        if item.seq < t.next_seq:
            return []  # duplicate of an item we already have
        if item.seq > t.next_seq:
            self._transfer = None
            return [Ack(peer, Result.INVALID_SEQUENCE, t.mission_type)]
        t.items.append(item)
        t.last_activity_s = now_s
        t.retries = 0
        if t.next_seq >= t.count:
            self._transfer = None
            return [Complete(peer, t.items, t.mission_type)]
        return [Request(peer, t.next_seq, t.mission_type)]

    def on_cancel(self, peer: Peer) -> None:
        if self._transfer is not None and self._transfer.peer == peer:
            self._transfer = None

    def on_timer(self, now_s: float) -> list[Action]:
        t = self._transfer
        if t is None or now_s - t.last_activity_s < self.item_timeout_s:
            return []
        if t.retries >= self.max_retries:
            self._transfer = None
            return [Ack(t.peer, Result.OPERATION_CANCELLED, t.mission_type)]
        t.retries += 1
        t.last_activity_s = now_s
        return [Request(t.peer, t.next_seq, t.mission_type)]


def bus_index_of_seq(seqs: list[int], seq: int) -> int:
    """The bus item a MAVLink seq starts at (the next navigation item at or after it)."""
    for i, s in enumerate(seqs):
        if s >= seq:
            return i
    return len(seqs)


def seq_of_bus_index(seqs: list[int], index: int) -> int:
    if 0 <= index < len(seqs):
        return seqs[index]
    return index
