"""QGroundControl's wire profile against the bundled ``fixedwing`` scenario (raw pymavlink over
UDP on 127.0.0.1, the real stack: plume + physics + autopilot + gateway, in lockstep).

The heartbeat says MAV_TYPE_FIXED_WING and MAV_AUTOPILOT_PX4; a mission as QGC's Plan view
makes it for a plane — a take-off item first, waypoints, then its landing pattern
(DO_LAND_START, its default final approach NAV_LOITER_TO_ALT, NAV_LAND) — is uploaded
(MISSION_ACK accepted), read back item for item, and flown with QGC's *Start Mission* (mode
Mission while disarmed, then ARM): the plane rolls along the runway and climbs on its heading,
passes every waypoint, lands on the approach line and disarms within ``LANDED_WITHIN_M`` of the
landing point.

Positions are measured from GLOBAL_POSITION_INT with the small-angle formula (not the
gateway's own frame conversion); the landing bound is the measured distance with a margin
(docs/qgroundcontrol.md, "Fixed-wing vehicles").
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from gcs_bridge.dialect import mavlink
from swarmbus.scenario import load_scenario
from tests.support.fixed_wing import bundled_plane_scenario
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, mission_item
from tests.support.procs import zenoh_network

SYSID = 1
TAKEOFF_ALT_M = 30.0
CRUISE_ALT_M = 40.0
# ENU metres from home; the plane stands on home with its nose west, into the wind
WAYPOINTS = [(-600.0, 300.0), (400.0, 300.0)]
APPROACH = (800.0, 0.0)  # the landing pattern's start: the approach runs west along y = 0
LANDING = (0.0, 0.0)
NAV_ACC_RAD_M = 20.0  # swarmbus/vehicles/aerosonde.toml's default, FixedWingParams
LANDED_WITHIN_M = 60.0  # measured 31.8-33.3 m (docs/qgroundcontrol.md, "Fixed-wing vehicles")
CMD_TAKEOFF, CMD_WAYPOINT, CMD_LAND = 22, 16, 21
CMD_LAND_START = 189
CMD_LOITER_TO_ALT = 31


def east_north(m: Any, lat0: float, lon0: float) -> tuple[float, float]:
    """ENU metres of a GLOBAL_POSITION_INT about (lat0, lon0), small-angle."""
    north = (m.lat * 1e-7 - lat0) * 111_320.0
    east = (m.lon * 1e-7 - lon0) * 111_320.0 * math.cos(math.radians(lat0))
    return east, north


def latlon(east: float, north: float, lat0: float, lon0: float) -> tuple[float, float]:
    return (
        lat0 + north / 111_320.0,
        lon0 + east / (111_320.0 * math.cos(math.radians(lat0))),
    )


def plan(lat0: float, lon0: float) -> list[Any]:
    """Take-off, two waypoints, then QGC's landing pattern: DO_LAND_START, the final approach,
    the landing (relative altitudes)."""
    # QGC's fixed-wing take-off item: param1 the minimum climb-out pitch (15°), its point ahead
    # on the runway heading
    takeoff_at = latlon(-300.0, 0.0, lat0, lon0)
    items = [mission_item(SYSID, 0, CMD_TAKEOFF, *takeoff_at, TAKEOFF_ALT_M, param1=15.0)]
    for e, n in WAYPOINTS:
        items.append(
            mission_item(SYSID, len(items), CMD_WAYPOINT, *latlon(e, n, lat0, lon0), CRUISE_ALT_M)
        )
    land_start = mavlink.MAVLink_mission_item_int_message(
        SYSID, 1, len(items), int(mavlink.MAV_FRAME_MISSION), CMD_LAND_START,
        0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0, 0,
    )  # fmt: skip
    items.append(land_start)
    # QGC's default final approach: loiter to altitude (heading required, 75 m clockwise, exit
    # on the tangent toward the landing point)
    lat, lon = latlon(*APPROACH, lat0, lon0)
    final_approach = mavlink.MAVLink_mission_item_int_message(
        SYSID, 1, len(items), int(mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT), CMD_LOITER_TO_ALT,
        0, 1, 1.0, 75.0, 0.0, 1.0, round(lat * 1e7), round(lon * 1e7), TAKEOFF_ALT_M, 0,
    )  # fmt: skip
    items.append(final_approach)
    items.append(mission_item(SYSID, len(items), CMD_LAND, *latlon(*LANDING, lat0, lon0), 0.0))
    return items


def fields(m: Any) -> tuple[Any, ...]:
    """An item as the wire carries it (NaN compared as a value)."""
    values = (
        m.seq, m.frame, m.command, m.autocontinue, m.param1, m.param2, m.param3, m.param4,
        m.x, m.y, m.z, m.mission_type,
    )  # fmt: skip
    return tuple("nan" if isinstance(v, float) and math.isnan(v) else v for v in values)


def test_qgc_uploads_and_flies_a_plane_mission_from_take_off_to_landing(tmp_path: Path) -> None:
    scenario, gcs_port, _ = bundled_plane_scenario(tmp_path / "scenario.toml")
    origin = load_scenario(scenario).world.origin
    lat0, lon0 = origin.lat_deg, origin.lon_deg
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["plane1"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
        MavClient(gcs_port) as c,
    ):
        c.beat = True  # as QGC: once a second
        hb = c.wait_standby(SYSID)
        assert hb.type == mavlink.MAV_TYPE_FIXED_WING
        assert hb.autopilot == mavlink.MAV_AUTOPILOT_PX4
        c.wait_type("GLOBAL_POSITION_INT", SYSID)  # the physics runs: a state to arm on

        items = plan(lat0, lon0)
        assert c.upload(SYSID, items) == mavlink.MAV_MISSION_ACCEPTED
        assert [fields(m) for m in c.download(SYSID)] == [fields(m) for m in items]

        c.set_mode(SYSID, 4, 4)  # QGC's Start Mission: the mode first, disarmed ...
        c.wait_mode(SYSID, 4, 4, armed=False)
        assert c.command(SYSID, 400, 1) == mavlink.MAV_RESULT_ACCEPTED  # ... then ARM
        c.wait_armed(SYSID)
        nav = [m.seq for m in items if m.command != CMD_LAND_START]
        c.wait_disarmed(SYSID, timeout_s=240.0)
        c.until(
            "every navigation item reached",
            lambda: len(c.logged("MISSION_ITEM_REACHED", SYSID)) >= len(nav),
            10.0,
        )
        last = c.wait_type("GLOBAL_POSITION_INT", SYSID)
        state = c.wait_type("EXTENDED_SYS_STATE", SYSID)

    track = [
        (*east_north(m, lat0, lon0), m.relative_alt * 1e-3)
        for m in c.logged("GLOBAL_POSITION_INT", SYSID)
    ]
    assert [m.seq for m in c.logged("MISSION_ITEM_REACHED", SYSID)] == nav
    # the take-off: along the runway (y = 0, westward) until it is well off the ground
    off = next(i for i, p in enumerate(track) if p[2] > 20.0)
    climb = [p for p in track[:off] if p[2] > 1.0]
    assert climb and all(abs(n) < 5.0 and e < 0.0 for e, n, _ in climb), climb[:3]
    assert max(z for *_, z in track) > TAKEOFF_ALT_M - 1.0
    for w in [*WAYPOINTS, APPROACH]:
        closest = min(math.dist(w, p[:2]) for p in track)
        print(f"waypoint {w}: closest {closest:.1f} m")
        assert closest < 2.0 * NAV_ACC_RAD_M, f"waypoint {w}: closest {closest:.1f} m"
    east, north = east_north(last, lat0, lon0)
    landed_m = math.dist((east, north), LANDING)
    print(f"landed {landed_m:.1f} m from the landing point, at ({east:.1f}, {north:.1f})")
    assert landed_m < LANDED_WITHIN_M
    assert abs(north - LANDING[1]) < 5.0  # on the approach line
    assert abs(last.relative_alt) < 1000  # mm: on the ground
    assert state.landed_state == mavlink.MAV_LANDED_STATE_ON_GROUND
