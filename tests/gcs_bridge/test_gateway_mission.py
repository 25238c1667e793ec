"""The mission protocol state machine and item conversion, without sockets."""

from __future__ import annotations

import dataclasses

import pytest

from gcs_bridge import mission as ms
from gcs_bridge.frames import enu_to_geodetic
from swarmbus.messages import MissionCommand, MissionItem
from swarmbus.scenario import Origin

ORIGIN = Origin()
HOME = ms.Place(ORIGIN.lat_deg, ORIGIN.lon_deg, ORIGIN.alt_m, ORIGIN)
QGC = ms.Peer("gcs", ("127.0.0.1", 14550), 255, 190)
OTHER = ms.Peer("gcs", ("127.0.0.1", 14551), 254, 190)
FENCE = 1


def wp(seq: int, e: float, n: float, rel_alt: float, command: int = ms.CMD_WAYPOINT) -> ms.WireItem:
    lat, lon, _ = enu_to_geodetic((e, n, 0.0), ORIGIN)
    return ms.WireItem(
        seq=seq,
        frame=ms.FRAME_RELATIVE_INT,
        command=command,
        x=round(lat * 1e7),
        y=round(lon * 1e7),
        z=rel_alt,
    )


def test_upload_requests_every_item_in_order_then_completes() -> None:
    up = ms.Uploader()
    assert up.on_count(QGC, 3, ms.MISSION_TYPE_MISSION, 0.0) == [
        ms.Request(QGC, 0, ms.MISSION_TYPE_MISSION)
    ]
    items = [wp(i, 10.0 * i, 0.0, 10.0) for i in range(3)]
    assert up.on_item(QGC, items[0], 0.1) == [ms.Request(QGC, 1, ms.MISSION_TYPE_MISSION)]
    assert up.on_item(QGC, items[0], 0.1) == []  # duplicate: ignored
    assert up.on_item(QGC, items[1], 0.2) == [ms.Request(QGC, 2, ms.MISSION_TYPE_MISSION)]
    (done,) = up.on_item(QGC, items[2], 0.3)
    assert isinstance(done, ms.Complete) and done.items == items
    assert not up.active


def test_absurd_counts_and_other_mission_types_are_refused() -> None:
    up = ms.Uploader()
    assert up.on_count(QGC, 65535, ms.MISSION_TYPE_MISSION, 0.0) == [
        ms.Ack(QGC, ms.Result.NO_SPACE, ms.MISSION_TYPE_MISSION)
    ]
    assert up.on_count(QGC, 3, 7, 0.0) == [ms.Ack(QGC, ms.Result.UNSUPPORTED, 7)]
    assert up.on_count(QGC, 3, ms.MISSION_TYPE_ALL, 0.0) == [
        ms.Ack(QGC, ms.Result.UNSUPPORTED, ms.MISSION_TYPE_ALL)
    ]
    assert not up.active
    (clear,) = up.on_count(QGC, 0, ms.MISSION_TYPE_MISSION, 0.0)
    assert isinstance(clear, ms.Complete) and clear.items == []


def test_out_of_order_item_ends_the_transfer_with_invalid_sequence() -> None:
    up = ms.Uploader()
    up.on_count(QGC, 3, ms.MISSION_TYPE_MISSION, 0.0)
    up.on_item(QGC, wp(0, 0, 0, 5), 0.1)
    assert up.on_item(QGC, wp(2, 0, 0, 5), 0.2) == [
        ms.Ack(QGC, ms.Result.INVALID_SEQUENCE, ms.MISSION_TYPE_MISSION)
    ]
    assert not up.active
    assert up.on_item(QGC, wp(1, 0, 0, 5), 0.3) == []  # no transfer any more


def test_an_item_of_another_mission_type_ends_the_transfer() -> None:
    up = ms.Uploader()
    up.on_count(QGC, 3, ms.MISSION_TYPE_MISSION, 0.0)
    fence = ms.WireItem(seq=0, frame=ms.FRAME_RELATIVE_INT, command=16, mission_type=1)
    assert up.on_item(QGC, fence, 0.1) == [ms.Ack(QGC, ms.Result.INVALID, ms.MISSION_TYPE_MISSION)]
    assert not up.active  # no re-requests for a transfer the client broke


def test_a_second_gcs_is_denied_while_one_uploads() -> None:
    up = ms.Uploader()
    up.on_count(QGC, 2, ms.MISSION_TYPE_MISSION, 0.0)
    assert up.on_count(OTHER, 2, ms.MISSION_TYPE_MISSION, 0.0) == [
        ms.Ack(OTHER, ms.Result.DENIED, ms.MISSION_TYPE_MISSION)
    ]
    assert up.on_item(OTHER, wp(0, 0, 0, 5), 0.1) == [
        ms.Ack(OTHER, ms.Result.DENIED, ms.MISSION_TYPE_MISSION)
    ]
    assert up.active


def test_silence_is_re_requested_then_cancelled() -> None:
    up = ms.Uploader(item_timeout_s=1.0, max_retries=2)
    up.on_count(QGC, 2, ms.MISSION_TYPE_MISSION, 0.0)
    assert up.on_timer(0.5) == []
    assert up.on_timer(1.1) == [ms.Request(QGC, 0, ms.MISSION_TYPE_MISSION)]
    assert up.on_timer(2.2) == [ms.Request(QGC, 0, ms.MISSION_TYPE_MISSION)]
    assert up.on_timer(3.3) == [ms.Ack(QGC, ms.Result.OPERATION_CANCELLED, ms.MISSION_TYPE_MISSION)]
    assert not up.active


def test_conversion_to_enu_folds_speed_items_and_keeps_seqs() -> None:
    wire = [
        ms.WireItem(seq=0, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_TAKEOFF, z=10.0),
        ms.WireItem(seq=1, frame=ms.FRAME_MISSION, command=ms.CMD_CHANGE_SPEED, param2=3.0),
        wp(2, 30.0, -5.0, 12.0),
        ms.WireItem(seq=3, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_LAND),
    ]
    c = ms.convert_upload(wire, HOME)
    assert c.seqs == [0, 2, 3]
    takeoff, way, land = c.items
    assert takeoff.command == MissionCommand.TAKEOFF
    assert (takeoff.x, takeoff.y, takeoff.z) == pytest.approx((0.0, 0.0, 10.0), abs=1e-6)
    assert (way.x, way.y, way.z) == pytest.approx((30.0, -5.0, 12.0), abs=0.01)
    assert way.speed_m_s == 3.0 and way.acceptance_radius_m == ms.DEFAULT_ACCEPTANCE_M
    assert land.command == MissionCommand.LAND
    assert ms.bus_index_of_seq(c.seqs, 1) == 1 and ms.seq_of_bus_index(c.seqs, 2) == 3


def test_do_land_start_is_a_marker_the_landing_keeps_its_seq() -> None:
    """QGC's fixed-wing landing pattern: DO_LAND_START (189), the final approach (a waypoint,
    or by default NAV_LOITER_TO_ALT 31: heading required, radius, exit on the tangent), then
    NAV_LAND; the loiter to altitude is flown as a waypoint at its point and altitude."""
    loiter_to_alt = dataclasses.replace(
        wp(3, 400.0, 50.0, 25.0, command=31), param1=1.0, param2=75.0, param3=0.0, param4=1.0
    )
    wire = [
        wp(0, 100.0, 0.0, 30.0),
        wp(1, 300.0, 0.0, 30.0),
        ms.WireItem(seq=2, frame=ms.FRAME_MISSION, command=189),
        loiter_to_alt,
        ms.WireItem(seq=4, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_LAND),
    ]
    c = ms.convert_upload(wire, HOME)
    assert c.seqs == [0, 1, 3, 4]
    assert [i.command for i in c.items] == [
        MissionCommand.WAYPOINT,
        MissionCommand.WAYPOINT,
        MissionCommand.WAYPOINT,
        MissionCommand.LAND,
    ]
    final = c.items[2]
    assert (final.x, final.y, final.z) == pytest.approx((400.0, 50.0, 25.0), abs=0.05)
    assert final.hold_s == 0.0 and final.acceptance_radius_m == ms.DEFAULT_ACCEPTANCE_M
    assert c.wire == wire  # downloaded as uploaded


@pytest.mark.parametrize(
    ("item", "result"),
    [
        (ms.WireItem(seq=0, frame=ms.FRAME_RELATIVE_INT, command=31000), ms.Result.UNSUPPORTED),
        (
            ms.WireItem(seq=0, frame=10, command=ms.CMD_WAYPOINT, x=1, y=1),
            ms.Result.UNSUPPORTED_FRAME,
        ),
        (
            ms.WireItem(
                seq=0, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_WAYPOINT, x=2_000_000_000, y=1
            ),
            ms.Result.INVALID_PARAM5_X,
        ),
        (
            ms.WireItem(
                seq=0,
                frame=ms.FRAME_RELATIVE_INT,
                command=ms.CMD_WAYPOINT,
                x=1,
                y=1,
                z=float("nan"),
            ),
            ms.Result.INVALID_PARAM7,
        ),
        (
            ms.WireItem(
                seq=0, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_WAYPOINT, x=1, y=1, param1=-3.0
            ),
            ms.Result.INVALID_PARAM1,
        ),
        (
            ms.WireItem(
                seq=0, frame=ms.FRAME_RELATIVE_INT, command=ms.CMD_WAYPOINT, param2=float("inf")
            ),
            ms.Result.INVALID_PARAM2,
        ),
    ],
)
def test_bad_items_give_the_right_mission_result(item: ms.WireItem, result: ms.Result) -> None:
    with pytest.raises(ms.MissionError) as err:
        ms.convert_upload([item], HOME)
    assert err.value.result == result


def test_autopilot_missions_download_as_relative_altitude_items() -> None:
    items = [
        MissionItem(command=MissionCommand.TAKEOFF, x=20.0, y=-4.0, z=10.0),
        MissionItem(x=40.0, y=-4.0, z=10.0, hold_s=2.0),
        MissionItem(command=MissionCommand.LAND, x=20.0, y=-4.0, z=0.0),
    ]
    wire = ms.wire_of_items(items, HOME)
    assert [w.command for w in wire] == [ms.CMD_TAKEOFF, ms.CMD_WAYPOINT, ms.CMD_LAND]
    assert all(w.frame == ms.FRAME_RELATIVE_INT for w in wire)
    back = ms.convert_upload(wire, HOME).items
    for a, b in zip(items, back, strict=True):
        assert (b.x, b.y, b.z) == pytest.approx((a.x, a.y, a.z), abs=0.02)
    assert back[1].hold_s == 2.0


def fence_item(seq: int, e: float, n: float, command: int, param1: float) -> ms.WireItem:
    w = wp(seq, e, n, 0.0, command)
    return ms.WireItem(**{**w.__dict__, "frame": ms.FRAME_GLOBAL_INT, "param1": param1})


def test_fence_polygons_and_circles_become_enu_zones() -> None:
    from gcs_bridge import plans

    inc, exc = plans.CMD_POLYGON_INCLUSION, plans.CMD_CIRCLE_EXCLUSION
    square = [(0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0)]
    wire = [fence_item(i, e, n, inc, 4) for i, (e, n) in enumerate(square)]
    wire.append(fence_item(4, 50.0, 50.0, exc, 10.0))
    zones = plans.convert_fence(wire, HOME)
    assert len(zones) == 2 and zones[0].inclusion and not zones[1].inclusion
    got = [c for vertex in zones[0].polygon_enu_m or [] for c in vertex]
    assert got == pytest.approx([c for vertex in square for c in vertex], abs=0.05)
    assert zones[1].center_enu_m == pytest.approx((50.0, 50.0), abs=0.05)
    assert zones[1].radius_m == 10.0
    with pytest.raises(ms.MissionError) as short:
        plans.convert_fence(wire[:3], HOME)  # a polygon announced with 4 vertices, 3 sent
    assert short.value.result == ms.Result.INVALID_PARAM1
    with pytest.raises(ms.MissionError) as bad_radius:
        plans.convert_fence([fence_item(0, 0.0, 0.0, exc, -1.0)], HOME)
    assert bad_radius.value.result == ms.Result.INVALID_PARAM1
    # A circle of radius 0 is how MAVSDK sends "polygons only"; PX4 keeps it and ignores it.
    empty_circle = fence_item(4, 50.0, 50.0, plans.CMD_CIRCLE_INCLUSION, 0.0)
    assert plans.convert_fence([*wire[:4], empty_circle], HOME) == zones[:1]
    (rally,) = plans.convert_rally([wp(0, 30.0, -20.0, 5.0, plans.CMD_RALLY_POINT)], HOME)
    assert rally == pytest.approx((30.0, -20.0, 5.0), abs=0.05)
    up = ms.Uploader()
    assert up.on_count(QGC, 5, FENCE, 0.0) == [ms.Request(QGC, 0, FENCE)]


def test_the_px4_scenario_carries_px4_sitls_defaults() -> None:
    """PX4 SITL's published defaults (PX4 user guide, parameter reference): home 47.397742 N,
    8.545594 E, 488 m; MIS_TAKEOFF_ALT 2.5 m; GF_MAX_HOR_DIST and GF_MAX_VER_DIST 0 (off);
    RTL_RETURN_ALT 60 m; NAV_DLL_ACT 0 (none); COM_OF_LOSS_T 1 s; MAVSDK's port 14540."""
    from swarmbus.scenario import load_scenario, resolve_scenario_path

    sc = load_scenario(resolve_scenario_path("px4"))
    assert [v.sysid for v in sc.vehicles] == [1]
    origin = sc.world.origin
    assert (origin.lat_deg, origin.lon_deg, origin.alt_m) == (47.397742, 8.545594, 488.0)
    fs = sc.failsafe
    assert fs.takeoff_altitude_m == 2.5 and fs.rtl_altitude_m == 60.0
    assert fs.geofence_max_distance_m == 0.0 and fs.geofence_max_altitude_m == 0.0
    assert fs.datalink_loss_action == "none" and fs.offboard_timeout_s == 1.0
    assert sc.gateway.api_port_base == 14540 and sc.gateway.gcs_port == 14550
    assert sc.time.mode == "realtime"
