"""PX4 workflows a MAVSDK user brings from PX4 SITL, through MAVSDK's own plugins (4.x, its
bundled C++ core) on the vehicle's API port, against the real stack (plume + physics +
autopilot + gateway).

One stack start covers several workflows in turn on one vehicle:
- a mission started on the ground without a takeoff item, with MAVSDK's "return to launch
  after mission": it takes off by itself, flies every item, returns and lands where it armed;
- the horizontal fence set through the param plugin (off by default, as PX4) refuses a go-to
  beyond it with COMMAND_DENIED and a status text naming GF_MAX_HOR_DIST and its value;
- an inclusion polygon uploaded with the geofence plugin stops a go-to outside it (one inside
  flies) and downloads again; a rally point uploaded with mission_raw is where RTL lands;
- the info plugin: PX4's version (v1.14.0 release), plumeswarm's as the vendor version, the
  sysid's identity in both uids, the lockstep's speed factor;
- offboard through the offboard plugin: a local NED position is measured from the vehicle's
  own origin (its spawn, not the world origin); body-frame velocity goes where the nose
  points; an attitude setpoint (nose down) accelerates the way the nose points; a global
  position setpoint is reached; NED velocity flies its direction; a position with a velocity
  feed-forward (and with an acceleration one too) is flown to along the straight line; an
  acceleration against the wind builds speed along its axis; a body yaw rate turns the nose
  the commanded way;
- orbit (action plugin, DO_ORBIT): the vehicle circles the given centre clockwise at the
  given radius, the heartbeat showing PX4's orbit mode (POSCTL / ORBIT);
- position mode with MANUAL_CONTROL sticks (manual_control plugin): forward stick flies
  along the nose, centred sticks stop; the heartbeat shows POSCTL;
- follow-me (follow_me plugin, FOLLOW_TARGET): the vehicle keeps FLW_TGT_DST behind a target
  walking north, at FLW_TGT_HT (MAVSDK's minimum, as PX4's, is 8 m);
- a QGroundControl ``.plan`` (mission without a takeoff item, ending in RTL; an inclusion
  polygon; a rally point) imported with mission_raw and uploaded: the vehicle takes off, flies
  it and lands at the rally point;
- then, as QGroundControl on the shared GCS port (raw MAVLink): a fence circle uploads as
  mission type 1, and QGC's *Start Mission* (mode Mission while disarmed, then ARM) flies a
  mission without a takeoff item to its end and its RTL.
"""

from __future__ import annotations

import asyncio
import json
import math
from importlib.metadata import version
from pathlib import Path
from typing import Any

import pytest
from packaging.version import Version

from gcs_bridge.dialect import mavlink
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import clients, first, mission_item, write_scenario
from tests.support.procs import zenoh_network
from tests.support.qgc_plan import MAV_TYPE_QUADROTOR, plan_document, simple_item

mavsdk = pytest.importorskip("mavsdk")

from mavsdk.asyncio.plugins.action import ActionAsync, ActionError  # noqa: E402
from mavsdk.asyncio.plugins.geofence import GeofenceAsync  # noqa: E402
from mavsdk.asyncio.plugins.info import InfoAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission import MissionAsync, MissionItem, MissionPlan  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.param import ParamAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402
from mavsdk.plugins.geofence import FenceType, GeofenceData, Point, Polygon  # noqa: E402
from mavsdk.plugins.info import InfoError  # noqa: E402
from mavsdk.plugins.mission_raw import MissionItem as RawItem  # noqa: E402

from tests.support.px4_flight import (  # noqa: E402
    ORIGIN,
    SPAWN_ENU,
    SYSID,
    TELEMETRY_HZ,
    connect,
    east_north_of,
    fly_uploaded_mission,
    horizontal_m,
    latlon,
    take_off,
)
from tests.support.px4_offboard import offboard_setpoints_as_px4  # noqa: E402

MISSION_ALT_M = 6.0


def waypoint(east_m: float, north_m: float, rel_alt_m: float) -> MissionItem:
    lat, lon = latlon(east_m, north_m)
    return MissionItem(
        latitude_deg=lat,
        longitude_deg=lon,
        relative_altitude_m=rel_alt_m,
        is_fly_through=True,
        acceptance_radius_m=1.0,
    )


async def received(get: Any, what: str, usable: Any = None, timeout_s: float = 10.0) -> Any:
    """An info getter's answer once what it is made of has come (the AUTOPILOT_VERSION the
    plugin asks for; for the speed factor, ATTITUDEs a sim time apart)."""
    deadline = asyncio.get_running_loop().time() + timeout_s
    while True:
        try:
            value = await get()
            if usable is None or usable(value):
                return value
        except InfoError as e:
            if e.result.name != "INFORMATION_NOT_RECEIVED_YET":
                raise
        assert asyncio.get_running_loop().time() < deadline, f"no {what} from the info plugin"
        await asyncio.sleep(0.2)


async def sim_seconds_per_wall_second(tel: Any, positions: int) -> float:
    """The lockstep's speed as the telemetry rate shows it: ``positions`` position messages
    take ``positions / TELEMETRY_HZ`` simulated seconds."""
    loop = asyncio.get_running_loop()
    stream = tel.subscribe_position()
    try:
        await first(stream, lambda p: True, "a position")
        start = loop.time()
        for _ in range(positions):
            await first(stream, lambda p: True, "a position")
        return positions / TELEMETRY_HZ / (loop.time() - start)
    finally:
        await stream.aclose()


async def info_as_px4(system: Any) -> None:
    """What the info plugin reads (AUTOPILOT_VERSION, ATTITUDE's time) against what
    docs/qgroundcontrol.md promises: PX4 v1.14.0 release, plumeswarm's version as the
    vendor's, "PLUME" then the sysid as the uid."""
    info, tel = InfoAsync(system), TelemetryAsync(system)
    v = await received(info.get_version, "version")
    assert (v.flight_sw_major, v.flight_sw_minor, v.flight_sw_patch) == (1, 14, 0), v
    assert v.flight_sw_version_type.name == "RELEASE", v
    ours = (*Version(version("plumeswarm")).release, 0, 0)[:3]
    vendor = (v.flight_sw_vendor_major, v.flight_sw_vendor_minor, v.flight_sw_vendor_patch)
    assert vendor == ours, f"vendor version {vendor}, plumeswarm {ours}"
    identity = b"PLUME" + SYSID.to_bytes(3, "big")
    ident = await received(info.get_identification, "identification")
    assert ident.legacy_uid == int.from_bytes(identity, "big"), hex(ident.legacy_uid)
    assert ident.hardware_uid.startswith(identity.hex()), ident.hardware_uid
    assert set(ident.hardware_uid[len(identity.hex()) :]) <= {"0"}, ident.hardware_uid
    product = await received(info.get_product, "product")
    assert (product.vendor_id, product.product_id) == (0, 0), product  # no hardware
    # MAVSDK averages over the last 50 ATTITUDEs, 12.5 s of sim time at 4 Hz: the same window
    await received(info.get_speed_factor, "speed factor", math.isfinite)
    measured = await sim_seconds_per_wall_second(tel, 50)
    factor = await info.get_speed_factor()
    assert 0.5 < factor / measured < 2.0, f"speed factor {factor}, telemetry shows {measured}"


async def mission_from_the_ground_with_rtl(system: Any) -> None:
    tel, act, mis = TelemetryAsync(system), ActionAsync(system), MissionAsync(system)
    await first(tel.subscribe_health(), lambda h: h.is_armable, "ready to arm")
    home = await first(tel.subscribe_position(), lambda p: True, "a position")
    e0, n0 = SPAWN_ENU
    plan = MissionPlan(
        [waypoint(e0 + 15.0, n0, MISSION_ALT_M), waypoint(e0 + 15.0, n0 + 8.0, MISSION_ALT_M)]
    )
    await mis.set_return_to_launch_after_mission(True)
    await mis.upload_mission(plan)
    await act.arm()
    await mis.start_mission()
    await first(tel.subscribe_in_air(), bool, "in the air after starting the mission")
    await first(
        tel.subscribe_position(),
        lambda p: p.relative_altitude_m > MISSION_ALT_M - 1.0,
        f"the climb to {MISSION_ALT_M} m",
    )
    await first(
        mis.subscribe_mission_progress(),
        lambda p: p.total > 0 and p.current == p.total,
        "mission progress to the end",
    )
    await first(tel.subscribe_armed(), lambda armed: not armed, "landed and disarmed", 180.0)
    landed = await first(tel.subscribe_position(), lambda p: True, "a position after landing")
    assert horizontal_m(landed, home) < 1.5, "return to launch did not land at home"


async def goto_refused_by_the_fence_parameter(system: Any) -> None:
    tel, act, param = TelemetryAsync(system), ActionAsync(system), ParamAsync(system)
    assert await param.get_param_float("GF_MAX_HOR_DIST") == 0.0, "PX4 default: no fence"
    await param.set_param_float("GF_MAX_HOR_DIST", 30.0)
    here = await first(tel.subscribe_position(), lambda p: True, "a position")
    texts: list[str] = []

    async def listen() -> None:
        async for t in tel.subscribe_status_text():
            texts.append(t.text)

    listener = asyncio.create_task(listen())
    try:
        e0, n0 = SPAWN_ENU
        lat, lon = latlon(e0 + 60.0, n0)
        with pytest.raises(ActionError) as refused:
            await act.goto_location(lat, lon, here.absolute_altitude_m, math.nan)
        assert refused.value.result.name == "COMMAND_DENIED", refused.value
        deadline = asyncio.get_running_loop().time() + 10.0
        while not any("GF_MAX_HOR_DIST 30 m" in t for t in texts):
            assert asyncio.get_running_loop().time() < deadline, f"status texts: {texts}"
            await asyncio.sleep(0.1)
    finally:
        listener.cancel()
    await param.set_param_float("GF_MAX_HOR_DIST", 0.0)


async def fence_stops_goto_and_rtl_lands_at_rally(system: Any) -> None:
    tel, act = TelemetryAsync(system), ActionAsync(system)
    fence, raw = GeofenceAsync(system), MissionRawAsync(system)
    e0, n0 = SPAWN_ENU
    corners = [(e0 - 30, n0 - 30), (e0 + 30, n0 - 30), (e0 + 30, n0 + 30), (e0 - 30, n0 + 30)]
    square = Polygon([Point(*latlon(e, n)) for e, n in corners], FenceType.INCLUSION)
    await fence.upload_geofence(GeofenceData(polygons=[square], circles=[]))
    polygon = await raw.download_geofence()
    assert len(polygon) == 4
    # The same polygon with an empty circle (radius 0), as clients send "polygons only": PX4
    # keeps it and ignores it; as an inclusion zone it would forbid every go-to, inside too.
    c = polygon[0]
    empty = RawItem(4, c.frame, 5003, 0, 1, 0.0, 0, 0, 0, c.x, c.y, 0.0, 1)
    await raw.upload_geofence([*polygon, empty])
    assert len(await raw.download_geofence()) == 5
    here = await first(tel.subscribe_position(), lambda p: True, "a position")
    with pytest.raises(ActionError) as refused:
        await act.goto_location(*latlon(e0 + 45.0, n0), here.absolute_altitude_m, math.nan)
    assert refused.value.result.name == "COMMAND_DENIED", refused.value
    await act.goto_location(*latlon(e0 + 20.0, n0), here.absolute_altitude_m, math.nan)
    lat, lon = latlon(e0 + 20.0, n0)
    await first(
        tel.subscribe_position(),
        lambda p: (
            abs(p.latitude_deg - lat) * 111_320 < 1.0 and abs(p.longitude_deg - lon) * 75_000 < 1.0
        ),
        "the go-to inside the fence",
    )
    rally_lat, rally_lon = latlon(e0 + 15.0, n0 + 10.0)
    rally = RawItem(
        0, 6, 5100, 0, 1, 0, 0, 0, 0, round(rally_lat * 1e7), round(rally_lon * 1e7), 0.0, 2
    )
    await raw.upload_rally_points([rally])
    await act.return_to_launch()
    await first(tel.subscribe_armed(), lambda armed: not armed, "landed and disarmed", 180.0)
    landed = await first(tel.subscribe_position(), lambda p: True, "a position after RTL")
    target = type("P", (), {"latitude_deg": rally_lat, "longitude_deg": rally_lon})()
    assert horizontal_m(landed, target) < 1.5, "RTL did not land at the closer rally point"
    await fence.clear_geofence()


def qgc_plan(path: Path) -> Path:
    """A QGroundControl plan file as its Plan view saves it (relative altitudes, frame 3)."""
    e0, n0 = SPAWN_ENU

    def item(seq: int, command: int, east: float, north: float, alt: float) -> dict[str, Any]:
        lat, lon = latlon(east, north)
        if command == 16:
            return simple_item(seq, command, 3, [0, 0, 0, None, lat, lon, alt])
        return simple_item(seq, command, 2, [0] * 7)

    fence = [latlon(e0 + de, n0 + dn) for de, dn in ((-50, -50), (50, -50), (50, 50), (-50, 50))]
    plan = plan_document(
        [
            item(0, 16, e0 + 10.0, n0 + 20.0, 6.0),
            item(1, 16, e0 + 20.0, n0 + 20.0, 6.0),
            item(2, 20, 0.0, 0.0, 0.0),
        ],
        (*latlon(e0, n0), ORIGIN.alt_m),
        MAV_TYPE_QUADROTOR,
        5,
        polygons=[{"inclusion": True, "polygon": [list(p) for p in fence], "version": 1}],
        rally=[[*latlon(e0 + 22.0, n0 + 22.0), 6.0]],
    )
    path.write_text(json.dumps(plan))
    return path


async def qgc_plan_imported_and_flown(system: Any, plan: Path) -> None:
    raw = MissionRawAsync(system)
    imported = await raw.import_qgroundcontrol_mission(str(plan))
    assert len(imported.mission_items) == 3 and len(imported.rally_items) == 1
    await raw.upload_mission(imported.mission_items)
    await raw.upload_geofence(imported.geofence_items)
    await raw.upload_rally_points(imported.rally_items)
    assert len(await raw.download_geofence()) == len(imported.geofence_items) == 4
    assert len(await raw.download_rallypoints()) == 1
    landed = await fly_uploaded_mission(system, "the imported mission", 180.0)
    e0, n0 = SPAWN_ENU
    assert math.dist(east_north_of(landed), (e0 + 22.0, n0 + 22.0)) < 1.5, "not at the rally point"


async def workflows(api_port: int, plan: Path) -> None:
    sdk, system = await connect(api_port)
    try:
        await info_as_px4(system)
        await mission_from_the_ground_with_rtl(system)
        await take_off(system, 5.0)
        await goto_refused_by_the_fence_parameter(system)
        await fence_stops_goto_and_rtl_lands_at_rally(system)
        await offboard_setpoints_as_px4(system)
        await qgc_plan_imported_and_flown(system, plan)
    finally:
        await sdk.__aexit__(None, None, None)


def qgc_fence_and_start_mission(gcs_port: int) -> None:
    accepted = int(mavlink.MAV_MISSION_ACCEPTED)
    with clients(gcs_port) as (c,):
        # heartbeats once a wall second, as QGC does: MAVSDK has gone, and a silent ground
        # station trips the seed scenario's data-link-loss RTL (NAV_DLL_ACT) mid-mission
        c.beat = True
        c.wait_standby(1)
        pos = c.wait_type("GLOBAL_POSITION_INT", 1)
        lat, lon = pos.lat * 1e-7, pos.lon * 1e-7
        circle = mavlink.MAVLink_mission_item_int_message(
            1, 1, 0, int(mavlink.MAV_FRAME_GLOBAL_INT), 5003, 0, 1, 200.0, 0, 0, 0,
            pos.lat, pos.lon, 0.0, 1,
        )  # fmt: skip
        assert c.upload(1, [circle], mission_type=1) == accepted
        east = lon + 10.0 / (111_320.0 * math.cos(math.radians(lat)))
        north = lat + 5.0 / 111_320.0
        items = [
            mission_item(1, 0, 16, lat, east, 5.0),
            mission_item(1, 1, 16, north, east, 5.0),
            mission_item(1, 2, 20, 0.0, 0.0, 0.0),
        ]
        assert c.upload(1, items) == accepted
        c.set_mode(1, 4, 4)  # QGC's Start Mission: the mode first, disarmed ...
        c.wait_mode(1, 4, 4, armed=False)
        assert c.command(1, 400, 1) == int(mavlink.MAV_RESULT_ACCEPTED)  # ... then ARM
        reached = [c.wait_type("MISSION_ITEM_REACHED", 1, timeout_s=90.0).seq for _ in range(2)]
        assert reached == [0, 1]
        c.wait_disarmed(1, timeout_s=120.0)


def test_px4_workflows_through_mavsdk_plugins(tmp_path: Path) -> None:
    scenario, gcs, api = write_scenario(tmp_path / "scenario.toml", 1)
    text = scenario.read_text()  # the seed's own 500 m fence out: the default applies
    scenario.write_text(text.replace("geofence_max_distance_m = 500.0\n", ""))
    assert scenario.read_text() != text
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
    ):
        asyncio.run(workflows(api, qgc_plan(tmp_path / "survey.plan")))
        qgc_fence_and_start_mission(gcs)
