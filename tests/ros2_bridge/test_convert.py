"""The conversions in closed form: a cmd_vel Twist turned by the heading, sim-time stamps, an
unavailable gas reading."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from ros2_bridge import convert as cv
from ros2_bridge import wire
from swarmbus.messages import ConcentrationReading, PlumeState
from swarmbus.scenario import load_scenario, resolve_scenario_path
from tests.support.messages_samples import STATE
from tests.support.ros2_probe import twist_cdr


def facing(yaw_deg: float) -> tuple[float, float, float, float]:
    """A level body turned ``yaw_deg`` counter-clockwise from east: (x, y, z, w)."""
    half = math.radians(yaw_deg) / 2
    return (0.0, 0.0, math.sin(half), math.cos(half))


@pytest.mark.parametrize(
    ("yaw_deg", "body", "enu"),
    [
        (0.0, (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)),  # facing east, forward: east
        (90.0, (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)),  # facing north, forward: north
        (90.0, (0.0, 1.0, 0.5), (-1.0, 0.0, 0.5)),  # facing north, left: west; up stays up
        (180.0, (2.0, 0.0, 0.0), (-2.0, 0.0, 0.0)),
    ],
)
def test_cmd_vel_is_turned_by_the_heading(yaw_deg, body, enu) -> None:
    state = msgspec.structs.replace(STATE, attitude_xyzw=facing(yaw_deg))
    vx, vy, vz = body
    twist = wire.decode(twist_cdr(vx, vy, vz, 0.0, 0.0, 0.3), cv.TWIST)
    sp = cv.setpoint_of(twist, state)
    assert sp.velocity_enu_m_s == pytest.approx(enu, abs=1e-12)
    assert sp.yaw_rate_deg_s == pytest.approx(math.degrees(0.3))


def test_a_non_finite_twist_is_refused() -> None:
    twist = wire.decode(twist_cdr(math.nan, 0, 0, 0, 0, 0), cv.TWIST)
    with pytest.raises(ValueError, match="finite"):
        cv.setpoint_of(twist, STATE)


def test_stamps_split_sim_time_into_seconds_and_nanoseconds() -> None:
    t = cv.stamp(12.345678901)
    assert (t.sec, t.nanosec) == (12, 345678901)


def test_an_unavailable_reading_is_nan_in_every_channel() -> None:
    r = ConcentrationReading(
        vehicle_id="uav1",
        sim_time_s=1.0,
        position_enu_m=(0.0, 0.0, 0.0),
        available=False,
        reported_g_m3=None,
        true_g_m3=None,
    )
    cloud = wire.decode(wire.encode(cv.gas(r), cv.GAS), cv.GAS)
    assert [c.name for c in cloud.channels] == list(cv.GAS_CHANNELS)
    assert all(math.isnan(float(c.values[0])) for c in cloud.channels)


def test_a_truncated_payload_is_a_wire_error() -> None:
    with pytest.raises(wire.WireError):
        wire.decode(twist_cdr(1, 0, 0, 0, 0, 0)[:20], cv.TWIST)


def test_a_filament_state_is_one_sphere_list_at_the_centres() -> None:
    centres = np.array([[1.0, 2.0, 3.0], [4.5, -1.0, 2.0]], dtype="<f4")
    radii = np.array([0.5, 1.5], dtype="<f4")
    state = PlumeState(
        sim_time_s=3.0,
        model="filament",
        count=2,
        centres_f32=centres.tobytes(),
        radii_f32=radii.tobytes(),
    )
    sc = load_scenario(resolve_scenario_path("filament"))
    msg = wire.decode(wire.encode(cv.markers(sc, 3.0, (), state), cv.MARKERS), cv.MARKERS)
    (spheres,) = [m for m in msg.markers if m.ns == "plume_state"]
    assert spheres.type == 7  # SPHERE_LIST
    assert [(p.x, p.y, p.z) for p in spheres.points] == [tuple(c) for c in centres.tolist()]
    assert spheres.scale.x == pytest.approx(2.0)  # twice the mean radius
    assert (spheres.header.stamp.sec, spheres.header.frame_id) == (3, "map")
