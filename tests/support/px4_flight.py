"""Where a vehicle is and how it gets there, as a MAVSDK user sees it through the telemetry and
action plugins (the one-vehicle scenario of tests/support/mavclient.py). Imports MAVSDK: a test
imports this only after ``pytest.importorskip("mavsdk")``."""

from __future__ import annotations

import asyncio
import math
from typing import Any

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

from gcs_bridge.frames import enu_to_geodetic
from swarmbus.scenario import Origin
from tests.support.mavclient import first

ORIGIN = Origin()
SPAWN_ENU = (20.0, 0.0)  # tests.support.mavclient.scenario_text, one vehicle
SYSID = 1  # ditto
TELEMETRY_HZ = 4.0  # ditto: GLOBAL_POSITION_INT per simulated second


async def connect(api_port: int) -> tuple[Mavsdk, Any]:
    """A ground station's MAVSDK listening on ``api_port`` (127.0.0.1) and the first system
    with an autopilot it hears; the caller exits the MAVSDK context."""
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    sdk = Mavsdk(config)
    await sdk.__aenter__()
    await sdk.add_any_connection(f"udpin://127.0.0.1:{api_port}")

    async def found() -> Any:
        while True:
            for s in await sdk.get_systems():
                if await s.has_autopilot():
                    return s
            await asyncio.sleep(0.2)

    return sdk, await asyncio.wait_for(found(), 120.0)


async def fly_uploaded_mission(system: Any, what: str, landed_within_s: float) -> Any:
    """Arm, start the uploaded mission, see it in the air, wait until it has landed and
    disarmed (within ``landed_within_s`` wall seconds); returns the position after it."""
    tel, act, raw = TelemetryAsync(system), ActionAsync(system), MissionRawAsync(system)
    await first(tel.subscribe_health(), lambda h: h.is_armable, "ready to arm")
    await act.arm()
    await raw.start_mission()
    await first(tel.subscribe_in_air(), bool, f"in the air on {what}")
    await first(
        tel.subscribe_armed(), lambda armed: not armed, "landed and disarmed", landed_within_s
    )
    return await first(tel.subscribe_position(), lambda p: True, f"a position after {what}")


def horizontal_m(a: Any, b: Any) -> float:
    """Distance between two telemetry positions (small-angle, metres)."""
    north = (a.latitude_deg - b.latitude_deg) * 111_320.0
    east = (a.longitude_deg - b.longitude_deg) * 111_320.0 * math.cos(math.radians(a.latitude_deg))
    return math.hypot(north, east)


def latlon(east_m: float, north_m: float) -> tuple[float, float]:
    lat, lon, _ = enu_to_geodetic((east_m, north_m, 0.0), ORIGIN)
    return lat, lon


async def take_off(system: Any, altitude_m: float) -> None:
    tel, act = TelemetryAsync(system), ActionAsync(system)
    await first(tel.subscribe_health(), lambda h: h.is_armable, "ready to arm")
    await act.set_takeoff_altitude(altitude_m)
    await act.arm()
    await act.takeoff()
    await first(
        tel.subscribe_position(),
        lambda p: p.relative_altitude_m > altitude_m - 0.5,
        f"at {altitude_m} m",
    )


def east_north_of(p: Any) -> tuple[float, float]:
    """ENU metres of a telemetry position (small-angle, about the origin)."""
    o = ORIGIN
    north = (p.latitude_deg - o.lat_deg) * 111_320.0
    east = (p.longitude_deg - o.lon_deg) * 111_320.0 * math.cos(math.radians(o.lat_deg))
    return east, north


async def arrive(tel: Any, east: float, north: float, what: str, within_m: float = 1.0) -> None:
    await first(
        tel.subscribe_position(),
        lambda p: math.dist(east_north_of(p), (east, north)) < within_m,
        what,
    )


async def moved(tel: Any, distance_m: float, what: str) -> tuple[float, float]:
    """The unit direction (east, north) of the next ``distance_m`` flown."""
    start = east_north_of(await first(tel.subscribe_position(), lambda p: True, "a position"))
    end = east_north_of(
        await first(
            tel.subscribe_position(),
            lambda p: math.dist(east_north_of(p), start) > distance_m,
            what,
            60.0,
        )
    )
    d = math.dist(end, start)
    return (end[0] - start[0]) / d, (end[1] - start[1]) / d
