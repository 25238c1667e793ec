"""MAVSDK (4.x, its bundled C++ core) flies the bundled ``fixedwing`` scenario's plane on its API
port as a script flies PX4 SITL's plane: the real stack (plume + physics + autopilot +
gateway) in lockstep, 127.0.0.1 only.

The scripts are the action, telemetry and mission kinds a PX4 user writes (only the
connection URL is the test's): wait for the health, arm, take off (PX4's fixed-wing take-off:
a runway roll and climb-out on the heading to MIS_TAKEOFF_ALT, then loiter — mode HOLD), read
the position and the airspeed (``fixedwing_metrics``), upload a mission with the mission
plugin (no speed, no acceptance radius: the plane's own FW_AIRSPD_TRIM and NAV_ACC_RAD) and
fly it to its end, return to launch (the plane loiters over home at RTL_RETURN_ALT), land
(straight ahead on the glide slope) and see it on the ground and disarmed. Then, as PX4's own
fixed-wing MAVSDK test does, import a QGroundControl plan with mission_raw (take-off item,
waypoints, the landing pattern DO_LAND_START, NAV_LOITER_TO_ALT, NAV_LAND), upload it, arm,
start it on the ground and wait until disarmed: at rest on the approach line past the landing
point.

Expected values are the scenario's and the type file's (read here with ``tomllib``), never
the autopilot's own numbers.
"""

from __future__ import annotations

import asyncio
import json
import math
import statistics
import tomllib
from pathlib import Path
from typing import Any

import pytest

from swarmbus.scenario import SCENARIOS_DIR
from tests.support.fixed_wing import bundled_plane_scenario
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import first
from tests.support.procs import REPO, zenoh_network
from tests.support.qgc_plan import MAV_TYPE_FIXED_WING, plan_document, simple_item

mavsdk = pytest.importorskip("mavsdk")

from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

from tests.support.px4_flight import connect, fly_uploaded_mission  # noqa: E402

SCENARIO = tomllib.loads((SCENARIOS_DIR / "fixedwing.toml").read_text())
TAKEOFF_ALT_M = SCENARIO["failsafe"]["takeoff_altitude_m"]
RTL_ALT_M = SCENARIO["failsafe"]["rtl_altitude_m"]
PLANE = tomllib.loads((REPO / "swarmbus" / "vehicles" / "aerosonde.toml").read_text())
TRIM_M_S = PLANE["fixed_wing"]["params"]["FW_AIRSPD_TRIM"]
LOITER_M = PLANE["fixed_wing"]["params"]["NAV_LOITER_RAD"]
NAV_ACC_RAD_M = 20.0  # FixedWingParams' default, not in the type file
WIND_M_S = SCENARIO["wind"]["speed_m_s"]
TELEMETRY_HZ = 4.0  # tests.support.fixed_wing.bundled_plane_scenario
# a waypoint counts as passed within NAV_ACC_RAD; the 4 Hz positions see the plane at most one
# sample's flight (at trim airspeed plus a tailwind) further out
PASSED_WITHIN_M = NAV_ACC_RAD_M + (TRIM_M_S + WIND_M_S) / TELEMETRY_HZ
MISSION_ALT_M = 50.0
WAYPOINTS = [(-800.0, 0.0), (-800.0, 600.0), (0.0, 600.0)]  # ENU metres from home
NAN = math.nan
CRUISE_ALT_M = 40.0  # the plan's waypoints
PLAN_APPROACH = (800.0, 0.0)  # the plan's final approach: the landing runs west along y = 0
PLAN_LANDED_WITHIN_M = 60.0  # at rest past the landing point (the QGC test's bound)


def metres(p: Any, home: Any) -> tuple[float, float]:
    """(east, north) of a telemetry position from home, small-angle."""
    north = (p.latitude_deg - home.latitude_deg) * 111_320.0
    east = (
        (p.longitude_deg - home.longitude_deg)
        * 111_320.0
        * math.cos(math.radians(home.latitude_deg))
    )
    return east, north


def latlon(home: Any, east: float, north: float) -> tuple[float, float]:
    return (
        home.latitude_deg + north / 111_320.0,
        home.longitude_deg + east / (111_320.0 * math.cos(math.radians(home.latitude_deg))),
    )


async def samples(stream: Any, n: int) -> list[Any]:
    out: list[Any] = []
    while len(out) < n:
        out.append(await first(stream, lambda _: True, f"{n} samples"))
    return out


async def until(cond: Any) -> None:
    while not cond():
        await asyncio.sleep(0.05)


async def takeoff_and_loiter(drone: Any) -> Any:
    """Arm, take off, wait for the loiter; returns home."""
    tel, act = TelemetryAsync(drone), ActionAsync(drone)
    await first(
        tel.subscribe_health(),
        lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable,
        "ready to arm",
    )
    home = await first(tel.subscribe_home(), lambda _: True, "home")
    assert await act.get_takeoff_altitude() == pytest.approx(TAKEOFF_ALT_M)
    # listening before the take-off: in lockstep the climb can be over (and the mode HOLD)
    # before a subscription made after the command's answer hears its first mode
    takeoff_mode = asyncio.create_task(
        first(tel.subscribe_flight_mode(), lambda m: m.name == "TAKEOFF", "mode takeoff")
    )
    await first(tel.subscribe_flight_mode(), lambda _: True, "a flight mode")
    await act.arm()
    await act.takeoff()
    await takeoff_mode
    await first(tel.subscribe_in_air(), bool, "in the air")
    await first(tel.subscribe_flight_mode(), lambda m: m.name == "HOLD", "the loiter", 180.0)
    pos = await first(tel.subscribe_position(), lambda _: True, "a position")
    assert abs(pos.relative_altitude_m - TAKEOFF_ALT_M) < 3.0, pos
    # a loiter at trim airspeed: a full circle, 2 pi 100 m / 25 m/s ≈ 25 s, at 4 Hz
    metrics = await samples(tel.subscribe_fixedwing_metrics(), 100)
    airspeeds = [m.airspeed_m_s for m in metrics]
    print(f"loiter airspeed {min(airspeeds):.2f}..{max(airspeeds):.2f} m/s")
    assert abs(statistics.median(airspeeds) - TRIM_M_S) < 1.5, airspeeds
    return home


async def fly_mission(drone: Any, home: Any) -> None:
    tel, mis = TelemetryAsync(drone), MissionAsync(drone)
    items = [
        MissionItem(
            latitude_deg=lat,
            longitude_deg=lon,
            relative_altitude_m=MISSION_ALT_M,
            speed_m_s=NAN,
            is_fly_through=True,
            gimbal_pitch_deg=NAN,
            gimbal_yaw_deg=NAN,
            loiter_time_s=NAN,
            camera_photo_interval_s=NAN,
            acceptance_radius_m=NAN,
            yaw_deg=NAN,
            camera_photo_distance_m=NAN,
        )
        for lat, lon in (latlon(home, e, n) for e, n in WAYPOINTS)
    ]
    await mis.set_return_to_launch_after_mission(False)
    await mis.upload_mission(MissionPlan(items))
    track: list[tuple[float, float]] = []

    async def record() -> None:
        async for p in tel.subscribe_position():
            track.append(metres(p, home))

    recorder = asyncio.create_task(record())
    try:
        await mis.start_mission()
        await first(
            mis.subscribe_mission_progress(),
            lambda p: p.total == len(WAYPOINTS) and p.current == p.total,
            "the mission's end",
            240.0,
        )
        # the positions up to the end and 3 s past it: the stream may lag the progress
        end = len(track) + int(3.0 * TELEMETRY_HZ)
        await asyncio.wait_for(until(lambda: len(track) >= end), 60.0)
    finally:
        recorder.cancel()
    for w in WAYPOINTS:
        closest = min(math.dist(w, p) for p in track)
        print(f"waypoint {w}: closest {closest:.1f} m")
        assert closest < PASSED_WITHIN_M, f"waypoint {w}: closest {closest:.1f} m"


async def return_and_land(drone: Any, home: Any) -> None:
    tel, act = TelemetryAsync(drone), ActionAsync(drone)
    await act.return_to_launch()
    await first(tel.subscribe_flight_mode(), lambda m: m.name == "RETURN_TO_LAUNCH", "mode RTL")
    await first(
        tel.subscribe_position(),
        lambda p: (
            math.hypot(*metres(p, home)) < LOITER_M + 30.0
            and abs(p.relative_altitude_m - RTL_ALT_M) < 3.0
        ),
        "home at the RTL altitude",
        240.0,
    )
    # settled on the circle (10 s), then a full circle of it (25 s at 4 Hz)
    circle = (await samples(tel.subscribe_position(), 140))[40:]
    radii = [math.hypot(*metres(p, home)) for p in circle]
    print(f"RTL loiter radius {min(radii):.1f}..{max(radii):.1f} m")
    assert min(radii) > LOITER_M - 20.0 and max(radii) < LOITER_M + 20.0, radii
    assert all(abs(p.relative_altitude_m - RTL_ALT_M) < 3.0 for p in circle)
    await act.land()
    await first(tel.subscribe_flight_mode(), lambda m: m.name == "LAND", "mode land")
    await first(tel.subscribe_armed(), lambda armed: not armed, "landed and disarmed", 240.0)
    landed = await first(tel.subscribe_landed_state(), lambda _: True, "a landed state")
    assert landed.name == "ON_GROUND", landed
    pos = await first(tel.subscribe_position(), lambda _: True, "a position")
    assert abs(pos.relative_altitude_m) < 1.0, pos
    print(f"landed {math.hypot(*metres(pos, home)):.0f} m from home")


def fixed_wing_plan(path: Path, home: Any) -> Path:
    """A QGroundControl plan for a plane as its Plan view saves it (relative altitudes, frame
    3): take-off, two waypoints, then the landing pattern — DO_LAND_START, the final approach
    (loiter to altitude, 75 m clockwise, exit on the tangent), NAV_LAND at home."""

    def at(east: float, north: float, alt: float) -> list[Any]:
        return [*latlon(home, east, north), alt]

    e_app, n_app = PLAN_APPROACH
    items = [
        simple_item(0, 22, 3, [15, 0, 0, None, *at(-300.0, 0.0, TAKEOFF_ALT_M)]),
        simple_item(1, 16, 3, [0, 0, 0, None, *at(-600.0, 300.0, CRUISE_ALT_M)]),
        simple_item(2, 16, 3, [0, 0, 0, None, *at(400.0, 300.0, CRUISE_ALT_M)]),
        simple_item(3, 189, 2, [0, 0, 0, 0, 0, 0, 0]),
        simple_item(4, 31, 3, [1, 75, 0, 1, *at(e_app, n_app, TAKEOFF_ALT_M)]),
        simple_item(5, 21, 3, [0, 0, 0, None, *at(0.0, 0.0, 0.0)]),
    ]
    home_lla = (home.latitude_deg, home.longitude_deg, home.absolute_altitude_m)
    plan = plan_document(items, home_lla, MAV_TYPE_FIXED_WING, TRIM_M_S)
    path.write_text(json.dumps(plan))
    return path


async def plan_flown_from_the_ground(drone: Any, plan: Path, home: Any) -> None:
    """PX4's own fixed-wing MAVSDK test: import a QGC plan with mission_raw, upload it, arm,
    start it on the ground, wait until disarmed."""
    raw = MissionRawAsync(drone)
    imported = await raw.import_qgroundcontrol_mission(str(plan))
    assert [i.command for i in imported.mission_items] == [22, 16, 16, 189, 31, 21]
    await raw.upload_mission(imported.mission_items)
    pos = await fly_uploaded_mission(drone, "the plan", 240.0)
    east, north = metres(pos, home)
    print(f"plan: at rest at ({east:.1f}, {north:.1f}) m from the landing point")
    assert math.hypot(east, north) < PLAN_LANDED_WITHIN_M
    assert abs(north) < 5.0  # on the approach line, y = 0


async def scripts(api_port: int, plan_path: Path) -> None:
    sdk, drone = await connect(api_port)
    try:
        home = await takeoff_and_loiter(drone)
        await fly_mission(drone, home)
        await return_and_land(drone, home)
        await plan_flown_from_the_ground(drone, fixed_wing_plan(plan_path, home), home)
    finally:
        await sdk.__aexit__(None, None, None)


def test_mavsdk_scripts_fly_the_plane(tmp_path: Path) -> None:
    scenario, _, api_port = bundled_plane_scenario(tmp_path / "scenario.toml")
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["plane1"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
    ):
        asyncio.run(scripts(api_port, tmp_path / "fixed_wing.plan"))
