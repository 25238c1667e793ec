"""The autopilot's pure logic flown against simple toy dynamics (no physics process, no bus)."""

from __future__ import annotations

import itertools
import math

import msgspec
import pytest

from agents.autopilot import Autopilot
from swarmbus.messages import (
    Arm,
    CommandReply,
    Disarm,
    FlightMode,
    GcsHeartbeat,
    Goto,
    Land,
    MissionCommand,
    MissionDownload,
    MissionFrame,
    MissionItem,
    MissionStart,
    MissionUpload,
    ReturnToLaunch,
    SetMode,
    Setpoint,
    Takeoff,
)
from swarmbus.scenario import Scenario, load_scenario
from tests.support.toy_physics import ToyWorld


def scenario(**failsafe: object) -> Scenario:
    sc = load_scenario()
    if failsafe:
        sc = msgspec.structs.replace(sc, failsafe=msgspec.structs.replace(sc.failsafe, **failsafe))
    return sc


def world(sc: Scenario, ids: list[str] | None = None) -> tuple[ToyWorld, dict[str, Autopilot]]:
    ids = ids or [v.id for v in sc.vehicles]
    aps = {vid: Autopilot(sc, vid) for vid in ids}
    w = ToyWorld(sc, aps)
    w.run(0.05)
    return w, aps


def ok(reply: CommandReply) -> None:
    assert reply.accepted, reply.reason


def take_off(w: ToyWorld, aps: dict[str, Autopilot], alt: float = 10.0) -> None:
    for ap in aps.values():
        ok(ap.handle(Arm()))
        ok(ap.handle(Takeoff(altitude_m=alt)))
    w.run(15.0, until=lambda: all(ap.modes.mode == FlightMode.HOLD for ap in aps.values()))
    assert all(ap.modes.mode == FlightMode.HOLD for ap in aps.values())


def test_three_iris_take_off_and_hold_within_20_cm() -> None:
    w, aps = world(scenario())
    take_off(w, aps)
    w.run(5.0)  # settle
    worst = 0.0

    def track() -> bool:
        nonlocal worst
        for vid in aps:
            p = w.vehicles[vid].p
            spawn = load_scenario().vehicle(vid).spawn_enu_m
            worst = max(worst, abs(p[2] - 10.0), math.hypot(p[0] - spawn[0], p[1] - spawn[1]))
        return False

    w.run(10.0, until=track)
    assert worst < 0.2


@pytest.mark.parametrize("vid", ["uav1", "uav2", "uav3"])
def test_scenario_mission_is_flown_and_ends_landed_and_disarmed(vid: str) -> None:
    sc = scenario()
    w, aps = world(sc, [vid])
    ap = aps[vid]
    ok(ap.handle(Arm()))
    ok(ap.handle(MissionStart()))
    w.run(120.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    status = ap.status()
    assert status.mission_finished and not status.armed and status.landed
    assert status.mission_items_reached == len(sc.vehicle(vid).mission)
    events = ap.modes.mission.drain_events()
    assert [e.index for e in events] == list(range(len(sc.vehicle(vid).mission)))
    last = sc.vehicle(vid).mission[-1]
    p = w.vehicles[vid].p
    assert math.hypot(p[0] - last.x, p[1] - last.y) < 0.5


def test_hexacopter_flies_a_square_and_lands() -> None:
    sc = load_scenario()
    hexa = msgspec.structs.replace(sc.vehicles[0], type="typhoon_h480", mission=[])
    sc = msgspec.structs.replace(sc, vehicles=[hexa])
    w, aps = world(sc)
    ap = aps[hexa.id]
    x0, y0, _ = hexa.spawn_enu_m
    square = [
        MissionItem(command=MissionCommand.TAKEOFF, x=x0, y=y0, z=8.0),
        MissionItem(x=x0 + 10, y=y0, z=8.0, hold_s=1.0),
        MissionItem(x=x0 + 10, y=y0 + 10, z=8.0),
        MissionItem(x=x0, y=y0 + 10, z=8.0),
        MissionItem(x=x0, y=y0, z=8.0),
        MissionItem(command=MissionCommand.LAND, x=x0, y=y0, z=0.0),
    ]
    ok(ap.handle(MissionUpload(items=square)))
    ok(ap.handle(Arm()))
    ok(ap.handle(MissionStart()))
    visited = set()

    def corners() -> bool:
        p = w.vehicles[hexa.id].p
        for i, item in enumerate(square[1:5]):
            if math.dist(p, (item.x, item.y, item.z)) < 1.0:
                visited.add(i)
        return ap.modes.mode == FlightMode.DISARMED

    w.run(120.0, until=corners)
    assert visited == {0, 1, 2, 3}
    assert ap.status().mission_finished and ap.status().landed


def test_land_command_touches_down_then_disarms() -> None:
    w, aps = world(scenario(), ["uav1"])
    take_off(w, aps, 5.0)
    ap = aps["uav1"]
    ok(ap.handle(Land()))
    w.run(30.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    assert ap.modes.mode == FlightMode.DISARMED and w.vehicles["uav1"].p[2] < 0.05
    assert not w.vehicles["uav1"].crashed


def test_global_frame_items_resolve_through_the_scenario_origin() -> None:
    sc = scenario()
    _, aps = world(sc, ["uav1"])
    ap = aps["uav1"]
    o = sc.world.origin
    # 0.0001° of latitude north of the origin ≈ 11.1 m north
    item = MissionItem(x=o.lat_deg + 1e-4, y=o.lon_deg, z=o.alt_m + 5.0, frame=MissionFrame.GLOBAL)
    ok(ap.handle(MissionUpload(items=[item])))
    got = ap.modes.mission.resolved[0]
    assert got.x == pytest.approx(0.0, abs=1e-3)
    assert got.y == pytest.approx(11.1, abs=0.1)
    assert got.z == pytest.approx(5.0, abs=1e-3)


# ------------------------------------------------------------------ failsafes
def test_datalink_loss_triggers_the_configured_action() -> None:
    sc = scenario(datalink_loss_action="land", datalink_timeout_s=2.0)
    w, aps = world(sc, ["uav1"])
    ap = aps["uav1"]
    ok(ap.handle(Arm()))
    ok(ap.handle(Takeoff(altitude_m=5.0)))

    def gcs_alive() -> bool:
        ok(ap.handle(GcsHeartbeat()))
        return False

    w.run(6.0, until=gcs_alive)
    assert ap.modes.mode == FlightMode.HOLD
    w.run(1.9)
    assert ap.modes.mode == FlightMode.HOLD  # not yet: the timeout is 2 s
    w.run(0.2)
    assert ap.modes.mode == FlightMode.LAND
    assert ap.status().failsafe == "ground-control link lost"
    ok(ap.handle(GcsHeartbeat()))
    assert ap.status().failsafe == ""


def test_no_gcs_ever_seen_never_trips_the_datalink_failsafe() -> None:
    w, aps = world(scenario(datalink_timeout_s=1.0), ["uav1"])
    take_off(w, aps, 3.0)
    w.run(5.0)
    assert aps["uav1"].modes.mode == FlightMode.HOLD


def test_datalink_required_refuses_arming_without_a_gcs() -> None:
    _, aps = world(scenario(datalink_required=True), ["uav1"])
    ap = aps["uav1"]
    reply = ap.handle(Arm())
    assert not reply.accepted and "ground-control link" in reply.reason
    ok(ap.handle(GcsHeartbeat()))
    ok(ap.handle(Arm()))


def test_geofence_breach_returns_to_launch_and_lands_home() -> None:
    sc = scenario(geofence_max_distance_m=15.0, rtl_altitude_m=6.0)
    w, aps = world(sc, ["uav1"])
    ap = aps["uav1"]
    take_off(w, aps, 4.0)
    # a setpoint stream flies it outward, past the fence (goto outside would be refused)
    outward = Setpoint(velocity_enu_m_s=(3.0, 0.0, 0.0))
    ok(ap.handle(outward))
    ok(ap.handle(SetMode(mode=FlightMode.OFFBOARD)))

    def stream() -> bool:
        ok(ap.handle(outward))
        return ap.modes.mode == FlightMode.RTL

    w.run(10.0, until=stream)
    assert ap.modes.mode == FlightMode.RTL and ap.status().failsafe.startswith("geofence")
    w.run(60.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    p = w.vehicles["uav1"].p
    home = ap.status().home_enu_m
    assert ap.modes.mode == FlightMode.DISARMED and math.hypot(p[0] - home[0], p[1] - home[1]) < 1


def test_offboard_stream_loss_falls_back_to_the_configured_action() -> None:
    w, aps = world(scenario(offboard_loss_action="land", offboard_timeout_s=0.5), ["uav1"])
    ap = aps["uav1"]
    take_off(w, aps, 4.0)
    ok(ap.handle(Setpoint(position_enu_m=(22.0, -4.0, 5.0))))
    ok(ap.handle(SetMode(mode=FlightMode.OFFBOARD)))
    assert ap.modes.mode == FlightMode.OFFBOARD
    w.run(1.0, until=lambda: ap.modes.mode != FlightMode.OFFBOARD)
    assert ap.modes.mode == FlightMode.LAND
    assert ap.status().failsafe == "offboard setpoint stream lost"


def test_crash_disarms_and_is_reported() -> None:
    w, aps = world(scenario(), ["uav1"])
    ap = aps["uav1"]
    take_off(w, aps, 6.0)
    ok(ap.handle(Disarm(force=True)))  # motors off in the air: it falls and hits hard
    w.run(5.0, until=lambda: w.vehicles["uav1"].crashed)
    w.run(0.1)
    status = ap.status()
    assert status.crashed and not status.armed and status.failsafe == "crash"
    reply = ap.handle(Arm())
    assert not reply.accepted and "crashed" in reply.reason


# ------------------------------------------------------------------ command refusals
def refused(ap: Autopilot, cmd: object, words: str, code: str = "denied") -> None:
    reply = ap.handle(cmd)
    assert not reply.accepted and reply.code == code, reply
    assert words in reply.reason, reply.reason


def test_commands_are_refused_with_the_right_reason() -> None:
    w, aps = world(scenario(geofence_max_altitude_m=50.0), ["uav1"])
    ap = aps["uav1"]
    refused(ap, Takeoff(altitude_m=5.0), "disarmed: arm before taking off")
    refused(ap, Land(), "disarmed")
    refused(ap, Disarm(), "already disarmed")
    ok(ap.handle(Arm()))
    refused(ap, Arm(), "already armed")
    refused(ap, Takeoff(altitude_m=80.0), "GF_MAX_VER_DIST 50 m", code="invalid")
    refused(ap, Goto(position_enu_m=(1.0, 2.0, 3.0)), "on the ground")
    refused(ap, SetMode(mode=FlightMode.OFFBOARD), "no offboard setpoint stream")
    ok(ap.handle(MissionUpload(items=[])))
    refused(ap, MissionStart(), "no mission uploaded")
    ok(ap.handle(MissionUpload(items=[MissionItem(x=30.0, y=0.0, z=5.0)])))
    refused(ap, MissionStart(start_index=3), "mission has 1 item", code="invalid")
    refused(
        ap,
        MissionUpload(items=[MissionItem(x=95.0, y=0.0, z=5.0, frame=MissionFrame.GLOBAL)]),
        "latitude",
        code="invalid",
    )
    ok(ap.handle(Takeoff(altitude_m=5.0)))
    w.run(5.0)
    refused(ap, Disarm(), "in the air")
    refused(ap, Takeoff(altitude_m=5.0), "already flying")
    ok(ap.handle(Land()))


def test_arming_in_the_air_is_refused() -> None:
    w, aps = world(scenario(), ["uav1"])
    ap = aps["uav1"]
    take_off(w, aps, 8.0)
    ok(ap.handle(Disarm(force=True)))
    w.run(0.3)
    assert not w.vehicles["uav1"].on_ground
    refused(ap, Arm(), "arming in the air")


def test_commands_before_any_state_are_refused_not_crashing() -> None:
    ap = Autopilot(load_scenario(), "uav1")
    refused(ap, Arm(), "no vehicle state yet")
    refused(ap, Land(), "no vehicle state yet")


def test_scenario_mission_is_downloadable_before_the_first_state() -> None:
    """A ground station that connects before the lockstep runs sees the scenario's mission."""
    sc = load_scenario()
    want = sc.vehicle("uav1").mission
    assert want, "the default scenario gives uav1 a mission"
    ap = Autopilot(sc, "uav1")
    reply = ap.handle(MissionDownload())
    assert reply.accepted and reply.mission == list(want)
    assert ap.status().mission_count == len(want)
    w, aps = world(sc, ["uav1"])  # after the first state: the uploaded mission, same items
    w.run(0.1)
    assert aps["uav1"].handle(MissionDownload()).mission == list(want)
    assert aps["uav1"].status().mission_count == len(want)


@pytest.mark.parametrize("first_alt_m", [1.0, 7.0])
def test_mission_started_on_the_ground_without_takeoff_item_climbs_first(
    first_alt_m: float,
) -> None:
    """PX4: the vehicle climbs vertically over its spawn to max(first item altitude,
    MIS_TAKEOFF_ALT above home) before heading for the first waypoint; an RTL item brings it
    home and it lands and disarms there."""
    sc = scenario(takeoff_altitude_m=2.5)
    vid = sc.vehicles[0].id
    w, aps = world(sc, [vid])
    ap = aps[vid]
    x0, y0, z0 = w.vehicles[vid].p
    items = [
        MissionItem(x=x0 + 15.0, y=y0, z=z0 + first_alt_m),
        MissionItem(x=x0 + 15.0, y=y0 + 10.0, z=z0 + first_alt_m),
        MissionItem(command=MissionCommand.RTL, x=0.0, y=0.0, z=0.0),
    ]
    ok(ap.handle(MissionUpload(items=items)))
    ok(ap.handle(Arm()))
    ok(ap.handle(MissionStart()))
    climb_m = max(first_alt_m, 2.5)
    drift_in_climb = 0.0

    def climbing() -> bool:
        nonlocal drift_in_climb
        p = w.vehicles[vid].p
        drift_in_climb = max(drift_in_climb, math.hypot(p[0] - x0, p[1] - y0))
        return p[2] - z0 > climb_m - 0.35

    w.run(20.0, until=climbing)
    assert w.vehicles[vid].p[2] - z0 > climb_m - 0.35, "never climbed"
    assert drift_in_climb < 0.5, f"left the spawn by {drift_in_climb:.2f} m while climbing"
    w.run(150.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    status = ap.status()
    assert status.mission_finished and status.landed and not status.armed
    assert [e.index for e in ap.modes.mission.drain_events()] == [0, 1, 2]
    p = w.vehicles[vid].p
    assert math.hypot(p[0] - x0, p[1] - y0) < 1.0, "RTL did not land at home"


def test_horizontal_fence_is_off_by_default_as_in_px4_and_refusals_name_the_parameter() -> None:
    from swarmbus.scenario import Failsafe

    assert Failsafe().geofence_max_distance_m == 0.0 and Failsafe().takeoff_altitude_m == 2.5
    assert load_scenario().failsafe.geofence_max_distance_m == 500.0  # the seed keeps its own
    far = scenario(geofence_max_distance_m=0.0)
    w, aps = world(far, ["uav1"])
    take_off(w, aps, 5.0)
    x, y, z = w.vehicles["uav1"].p
    ok(aps["uav1"].handle(Goto(position_enu_m=(x + 2000.0, y, z))))
    w2, aps2 = world(scenario(geofence_max_distance_m=30.0), ["uav1"])
    take_off(w2, aps2, 5.0)
    x, y, z = w2.vehicles["uav1"].p
    refused(aps2["uav1"], Goto(position_enu_m=(x + 60.0, y, z)), "GF_MAX_HOR_DIST 30 m", "invalid")


def test_uploaded_zones_allow_inside_one_inclusion_and_outside_every_exclusion() -> None:
    from agents.geofence import zones_violation
    from swarmbus.messages import FenceZone

    square = FenceZone(polygon_enu_m=[(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0)])
    far = FenceZone(center_enu_m=(500.0, 0.0), radius_m=20.0)
    hole = FenceZone(inclusion=False, center_enu_m=(50.0, 50.0), radius_m=10.0)
    zones = [square, far, hole]
    assert zones_violation(zones, 10.0, 10.0) is None
    assert zones_violation(zones, 510.0, 5.0) is None  # inside the other inclusion zone
    assert "inclusion" in (zones_violation(zones, 150.0, 50.0) or "")
    assert "exclusion zone 2" in (zones_violation(zones, 52.0, 48.0) or "")
    assert zones_violation([], 1e6, 1e6) is None


def test_uploaded_fence_refuses_goto_outside_and_one_leaving_out_home() -> None:
    from swarmbus.messages import FenceZone, GeofenceUpload, RallyUpload

    w, aps = world(scenario(), ["uav1"])
    ap = aps["uav1"]
    x, y, z = w.vehicles["uav1"].p
    elsewhere = FenceZone(center_enu_m=(x + 500.0, y), radius_m=20.0)
    refused(ap, GeofenceUpload(zones=[elsewhere]), "home is not allowed", "invalid")
    near = FenceZone(center_enu_m=(x, y), radius_m=30.0)
    ok(ap.handle(GeofenceUpload(zones=[near])))
    take_off(w, aps, 5.0)
    refused(ap, Goto(position_enu_m=(x + 40.0, y, z + 5.0)), "outside the inclusion", "invalid")
    ok(ap.handle(Goto(position_enu_m=(x + 20.0, y, z + 5.0))))
    # rally point closer than home: RTL lands there (PX4's RTL_TYPE 0)
    ok(ap.handle(RallyUpload(points_enu_m=[(x + 25.0, y + 5.0, z)])))
    w.run(15.0)
    ok(ap.handle(ReturnToLaunch()))
    w.run(90.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    p = w.vehicles["uav1"].p
    assert math.hypot(p[0] - (x + 25.0), p[1] - (y + 5.0)) < 1.0, p


def _offboard_with(w: ToyWorld, ap: Autopilot, sp: Setpoint, seconds: float) -> None:
    ok(ap.handle(sp))
    if ap.modes.mode != FlightMode.OFFBOARD:
        ok(ap.handle(SetMode(mode=FlightMode.OFFBOARD)))

    def stream() -> bool:
        ok(ap.handle(sp))
        return False

    w.run(seconds, until=stream)
    assert ap.modes.mode == FlightMode.OFFBOARD


def test_offboard_acceleration_yaw_rate_and_body_rates_act_in_their_frames() -> None:
    from agents.control import yaw_of

    sc = scenario(geofence_max_distance_m=0.0)
    sc = msgspec.structs.replace(sc, wind=msgspec.structs.replace(sc.wind, speed_m_s=0.0))
    w, aps = world(sc, ["uav1"])
    ap = aps["uav1"]
    take_off(w, aps, 8.0)
    # acceleration alone, 1.5 m/s² north in still air: no velocity loop, the speed keeps
    # growing (≈ 3 m/s after 2 s, less the drag and the time to tilt)
    _offboard_with(w, ap, Setpoint(acceleration_enu_m_s2=(0.0, 1.5, 0.0)), 2.0)
    v = w.vehicles["uav1"].v
    assert 2.2 < v[1] < 3.1 and abs(v[0]) < 0.2, v  # vz: whatever the take-off left
    # velocity with a yaw rate of 30 °/s (ENU, counter-clockwise) for 2 s: yaw grows ≈ 60°
    yaw0 = yaw_of(ap.est.attitude_xyzw)
    _offboard_with(w, ap, Setpoint(velocity_enu_m_s=(0.0, 0.0, 0.0), yaw_rate_deg_s=30.0), 2.0)
    turned = math.degrees(yaw_of(ap.est.attitude_xyzw) - yaw0)
    assert 45.0 < (turned + 180.0) % 360.0 - 180.0 < 65.0, turned
    # body rates: 0.5 rad/s about body z (FLU: counter-clockwise seen from above)
    yaw1 = yaw_of(ap.est.attitude_xyzw)
    iris_hover = 0.0
    for vt in (ap.controller,):
        iris_hover = vt.mass * 9.80665 / vt.max_thrust_n
    _offboard_with(w, ap, Setpoint(body_rates_rad_s=(0.0, 0.0, 0.5), thrust=iris_hover), 1.0)
    spun = math.degrees(yaw_of(ap.est.attitude_xyzw) - yaw1)
    assert 20.0 < (spun + 180.0) % 360.0 - 180.0 < 32.0, spun


def test_com_obl_act_speaks_px4s_codes() -> None:
    from swarmbus.messages import GetParams, SetParam

    ap = Autopilot(load_scenario(), "uav1")
    ok(ap.handle(SetParam(name="COM_OBL_ACT", value=0.0)))  # PX4: 0 land
    assert ap.modes.failsafe.offboard_loss_action == "land"
    ok(ap.handle(SetParam(name="COM_OBL_ACT", value=2.0)))  # PX4: 2 return
    assert ap.modes.failsafe.offboard_loss_action == "rtl"
    assert (ap.handle(GetParams()).params or {})["COM_OBL_ACT"] == 2.0
    refused(ap, SetParam(name="COM_OBL_ACT", value=3.0), "0 land, 1 hold, 2 rtl", "invalid")
    ok(ap.handle(SetParam(name="NAV_DLL_ACT", value=3.0)))  # NAV_DLL_ACT: 3 land
    assert ap.modes.failsafe.datalink_loss_action == "land"


def test_orbit_circles_clockwise_at_its_radius_facing_the_centre() -> None:
    from agents.control import yaw_of
    from swarmbus.messages import Orbit

    w, aps = world(scenario(geofence_max_distance_m=0.0), ["uav1"])
    ap = aps["uav1"]
    refused(ap, Orbit(center_enu_m=(0.0, 0.0, 5.0), radius_m=5.0, speed_m_s=2.0), "not flying")
    take_off(w, aps, 6.0)
    x, y, z = w.vehicles["uav1"].p
    cx, cy = x + 8.0, y
    ok(ap.handle(Orbit(center_enu_m=(cx, cy, z), radius_m=8.0, speed_m_s=2.0)))
    w.run(15.0)  # settle on the circle
    angles = []
    worst = 0.0

    def track() -> bool:
        p = w.vehicles["uav1"].p
        worst_r = abs(math.hypot(p[0] - cx, p[1] - cy) - 8.0)
        nonlocal worst
        worst = max(worst, worst_r)
        angles.append(math.atan2(p[1] - cy, p[0] - cx))
        return False

    w.run(10.0, until=track)
    steps = [(b - a + math.pi) % (2 * math.pi) - math.pi for a, b in itertools.pairwise(angles)]
    swept = float(sum(steps))
    # 2 m/s on an 8 m circle for 10 s: −2.5 rad (clockwise is negative in ENU)
    assert -2.8 < swept < -2.1, swept
    assert worst < 0.8, worst
    p = w.vehicles["uav1"].p
    to_centre = math.atan2(cy - p[1], cx - p[0])
    yaw = yaw_of(ap.est.attitude_xyzw)
    assert abs((yaw - to_centre + math.pi) % (2 * math.pi) - math.pi) < math.radians(10)
    ok(ap.handle(Land()))
