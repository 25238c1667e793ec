"""Geofence (mission type 1) and rally points (mission type 2) of the mission protocol, as
PX4 takes them: fence polygons are runs of vertex items whose param1 is the vertex count,
circles carry their radius in param1; rally points are positions. Only latitude and longitude
of fence items matter (the altitude limit is GF_MAX_VER_DIST)."""

from __future__ import annotations

import math

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import geodetic_to_enu
from gcs_bridge.mission import MissionError, Place, Result, WireItem, item_position_enu
from swarmbus.messages import MAX_FENCE_VERTICES, FenceZone

CMD_FENCE_RETURN_POINT = int(mavlink.MAV_CMD_NAV_FENCE_RETURN_POINT)
CMD_POLYGON_INCLUSION = int(mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION)
CMD_POLYGON_EXCLUSION = int(mavlink.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
CMD_CIRCLE_INCLUSION = int(mavlink.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION)
CMD_CIRCLE_EXCLUSION = int(mavlink.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)
CMD_RALLY_POINT = int(mavlink.MAV_CMD_NAV_RALLY_POINT)

_POLYGON = {CMD_POLYGON_INCLUSION, CMD_POLYGON_EXCLUSION}
_CIRCLE = {CMD_CIRCLE_INCLUSION, CMD_CIRCLE_EXCLUSION}
_INCLUSION = {CMD_POLYGON_INCLUSION, CMD_CIRCLE_INCLUSION}


def _horizontal(w: WireItem, here: Place) -> tuple[float, float]:
    lat, lon = w.x * 1e-7, w.y * 1e-7
    if not -90.0 <= lat <= 90.0:
        raise MissionError(Result.INVALID_PARAM5_X, w.seq, f"latitude {lat} out of range")
    if not -180.0 <= lon <= 180.0:
        raise MissionError(Result.INVALID_PARAM6_Y, w.seq, f"longitude {lon} out of range")
    e, n, _ = geodetic_to_enu(lat, lon, here.origin.alt_m, here.origin)
    return e, n


def _vertex_count(w: WireItem, left: int) -> int:
    n = w.param1
    if not (math.isfinite(n) and n == int(n) and 3 <= n <= min(left, MAX_FENCE_VERTICES)):
        raise MissionError(Result.INVALID_PARAM1, w.seq, f"polygon vertex count {n}")
    return int(n)


def convert_fence(wire: list[WireItem], here: Place) -> list[FenceZone]:
    """Fence zones (ENU) of a complete fence upload, or :class:`MissionError`."""
    zones: list[FenceZone] = []
    i = 0
    while i < len(wire):
        w = wire[i]
        if w.command in _POLYGON:
            n = _vertex_count(w, len(wire) - i)
            run = wire[i : i + n]
            for v in run:
                if v.command != w.command or v.param1 != w.param1:
                    raise MissionError(Result.INVALID, v.seq, "polygon ends before its count")
            vertices = [_horizontal(v, here) for v in run]
            zones.append(FenceZone(inclusion=w.command in _INCLUSION, polygon_enu_m=vertices))
            i += n
        elif w.command in _CIRCLE and w.param1 == 0.0:
            i += 1  # kept for download and ignored, as PX4 does: MAVSDK's "polygons only"
        elif w.command in _CIRCLE:
            if not (math.isfinite(w.param1) and 0.0 < w.param1 <= 1e6):
                raise MissionError(Result.INVALID_PARAM1, w.seq, f"circle radius {w.param1}")
            zones.append(
                FenceZone(
                    inclusion=w.command in _INCLUSION,
                    center_enu_m=_horizontal(w, here),
                    radius_m=float(w.param1),
                )
            )
            i += 1
        elif w.command == CMD_FENCE_RETURN_POINT:
            i += 1  # kept for download; breaches return home (RTL), as PX4 multicopters do
        else:
            raise MissionError(Result.UNSUPPORTED, w.seq, f"command {w.command} is not a fence")
    return zones


def convert_rally(wire: list[WireItem], here: Place) -> list[tuple[float, float, float]]:
    """Rally points (ENU) of a complete rally upload, or :class:`MissionError`."""
    points = []
    for w in wire:
        if w.command != CMD_RALLY_POINT:
            raise MissionError(Result.UNSUPPORTED, w.seq, f"command {w.command} is not rally")
        points.append(item_position_enu(w, here))
    return points
