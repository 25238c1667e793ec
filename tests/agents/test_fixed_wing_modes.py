"""The Aerosonde's modes one after the other in the fused runner, 3 m/s wind: take-off and
hold (loiter over the take-off point), orbit, RTL (loiter over home at the RTL altitude),
land straight ahead. Circles are measured from the physics' positions against the commanded
centres and radii."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest

from plumeswarm.experiments.fused import FusedRunner
from swarmbus.messages import (
    Arm,
    CommandReply,
    FlightMode,
    Land,
    Orbit,
    RejectCode,
    ReturnToLaunch,
    SetMode,
    Takeoff,
    VehicleState,
)
from swarmbus.vehicle_types import load_vehicle_type
from tests.support.fixed_wing import plane_scenario

FW = load_vehicle_type("aerosonde").fixed_wing
assert FW is not None
LOITER_R = FW.params.nav_loiter_rad
ORBIT = Orbit(center_enu_m=(300.0, 300.0, 45.0), radius_m=120.0, speed_m_s=-22.0)

# seconds → command
PLAN: dict[int, object] = {
    0: Arm(),
    1: Takeoff(altitude_m=30.0),
    60: ORBIT,
    140: ReturnToLaunch(),
    230: SetMode(mode=FlightMode.OFFBOARD),
    231: Land(),
}


@dataclass
class Run:
    states: list[VehicleState] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    replies: dict[int, CommandReply] = field(default_factory=dict)


@pytest.fixture(scope="module")
def run() -> Run:
    out = Run()
    with FusedRunner(
        plane_scenario("rtl_altitude_m = 50.0", "spawn_yaw_deg = 90.0"), plume=False
    ) as fused:
        ap = fused.flights["p"].autopilot
        for k in range(300 * 120):
            if k % 120 == 0 and k // 120 in PLAN:
                out.replies[k // 120] = fused.command("p", PLAN[k // 120])
            out.states.append(fused.step(1)[0])
            out.modes.append(str(ap.status().mode))
    return out


def window(run: Run, t0: float, t1: float) -> list[VehicleState]:
    return run.states[int(t0 * 120) : int(t1 * 120)]


def radii(states: list[VehicleState], cx: float, cy: float) -> list[float]:
    return [math.hypot(s.position_enu_m[0] - cx, s.position_enu_m[1] - cy) for s in states]


def test_take_off_then_loiter_over_the_take_off_point(run: Run) -> None:
    assert all(r.accepted for t, r in run.replies.items() if t != 230)
    assert "hold" in run.modes[: 60 * 120]
    loiter = window(run, 30.0, 60.0)
    r = radii(loiter, 0.0, 0.0)  # took off from the origin, loiters over it
    assert min(r) > LOITER_R - 15.0 and max(r) < LOITER_R + 15.0
    assert all(abs(s.position_enu_m[2] - 30.0) < 2.0 for s in loiter)


def test_orbit_at_its_centre_radius_and_direction(run: Run) -> None:
    cx, cy, cz = ORBIT.center_enu_m
    circle = window(run, 100.0, 140.0)
    r = radii(circle, cx, cy)
    assert ORBIT.radius_m - 10.0 < min(r) and max(r) < ORBIT.radius_m + 10.0
    assert all(abs(s.position_enu_m[2] - cz) < 2.0 for s in circle)
    # negative speed: counter-clockwise seen from above (positive angular momentum about z)
    for s in circle:
        (x, y, _), (vx, vy, _) = s.position_enu_m, s.velocity_enu_m_s
        assert (x - cx) * vy - (y - cy) * vx > 0.0


def test_rtl_loiters_over_home_at_the_rtl_altitude(run: Run) -> None:
    circle = window(run, 180.0, 230.0)
    r = radii(circle, 0.0, 0.0)
    assert min(r) > LOITER_R - 15.0 and max(r) < LOITER_R + 15.0
    assert all(abs(s.position_enu_m[2] - 50.0) < 2.0 for s in circle)
    assert set(run.modes[(180 * 120) : (230 * 120)]) == {"rtl"}


def test_offboard_is_refused_and_land_lands_straight_ahead(run: Run) -> None:
    refused = run.replies[230]
    assert not refused.accepted and refused.code == RejectCode.UNSUPPORTED
    assert "fixed-wing" in refused.reason
    assert not any(s.crashed for s in run.states)
    assert run.modes[-1] == "disarmed"
    last = run.states[-1]
    assert last.on_ground and math.hypot(*last.velocity_enu_m_s[:2]) < 1.0
