"""Uploaded geofence zones (polygons and circles, inclusion and exclusion) as PX4 checks them:
a point is allowed when it lies inside at least one inclusion zone (if there is any) and
outside every exclusion zone. Horizontal only; the altitude limit is GF_MAX_VER_DIST."""

from __future__ import annotations

import math

from swarmbus.messages import FenceZone


def inside_polygon(x: float, y: float, polygon: list[tuple[float, float]]) -> bool:
    """Even-odd ray casting (a point on an edge may fall either way)."""
    inside = False
    x1, y1 = polygon[-1]
    for x2, y2 in polygon:
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
        x1, y1 = x2, y2
    return inside


def inside_zone(x: float, y: float, zone: FenceZone) -> bool:
    if zone.polygon_enu_m is not None:
        return inside_polygon(x, y, list(zone.polygon_enu_m))
    if zone.center_enu_m is not None and zone.radius_m is not None:
        cx, cy = zone.center_enu_m
        return math.hypot(x - cx, y - cy) <= zone.radius_m
    return False


def zone_error(zone: FenceZone) -> str | None:
    """Why a zone is unusable (neither a polygon nor a circle), or None."""
    is_polygon = zone.polygon_enu_m is not None
    is_circle = zone.center_enu_m is not None and zone.radius_m is not None
    if is_polygon == is_circle:
        return "a zone is either a polygon (3+ vertices) or a circle (centre and radius)"
    return None


def zones_violation(zones: list[FenceZone], x: float, y: float) -> str | None:
    """Which uploaded zone a horizontal position breaks, or None."""
    inclusions = [i for i, z in enumerate(zones) if z.inclusion]
    if inclusions and not any(inside_zone(x, y, zones[i]) for i in inclusions):
        which = "zone " + ", ".join(str(i) for i in inclusions)
        return f"geofence: outside the inclusion {which}"
    for i, zone in enumerate(zones):
        if not zone.inclusion and inside_zone(x, y, zone):
            return f"geofence: inside the exclusion zone {i}"
    return None
