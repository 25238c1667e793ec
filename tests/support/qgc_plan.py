"""QGroundControl ``.plan`` files as its Plan view saves them (JSON: mission, geofence and rally
points), for the tests that import them with MAVSDK's ``mission_raw``."""

from __future__ import annotations

from typing import Any

MAV_TYPE_FIXED_WING = 1
MAV_TYPE_QUADROTOR = 2


def simple_item(seq: int, command: int, frame: int, params: list[Any]) -> dict[str, Any]:
    """A plan's SimpleItem (``params``: param1..7, None where QGC writes NaN)."""
    return {
        "type": "SimpleItem",
        "autoContinue": True,
        "command": command,
        "doJumpId": seq + 1,
        "frame": frame,
        "params": params,
    }


def plan_document(
    items: list[dict[str, Any]],
    home: tuple[float, float, float],
    vehicle_type: int,
    cruise_m_s: float,
    polygons: list[dict[str, Any]] | None = None,
    rally: list[list[float]] | None = None,
) -> dict[str, Any]:
    """A PX4 plan (firmware type 12) of ``items``, planned from ``home`` (lat, lon, AMSL)."""
    return {
        "fileType": "Plan",
        "version": 1,
        "groundStation": "QGroundControl",
        "mission": {
            "version": 2,
            "firmwareType": 12,
            "vehicleType": vehicle_type,
            "cruiseSpeed": cruise_m_s,
            "hoverSpeed": 3,
            "plannedHomePosition": list(home),
            "items": items,
        },
        "geoFence": {"version": 2, "circles": [], "polygons": polygons or []},
        "rallyPoints": {"version": 2, "points": rally or []},
    }
