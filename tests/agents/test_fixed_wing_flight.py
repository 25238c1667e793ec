"""The Aerosonde flies a mission in the fused runner (the same World and autopilot as the
distributed stack) in a 3 m/s wind: runway take-off, four waypoints with a loiter, approach
and landing. Measured against the scenario (the waypoints, the wind), never against the
pilot's own numbers: airspeed is |velocity − wind| from the physics' state."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import pytest

from plumeswarm.experiments.fused import FusedRunner
from swarmbus.messages import Arm, Goto, MissionItem, MissionStart, MissionUpload, VehicleState
from swarmbus.scenario import Scenario
from swarmbus.vehicle_types import load_vehicle_type
from tests.support.fixed_wing import WIND_ENU_M_S, plane_scenario

WIND = WIND_ENU_M_S
LAND = (0.0, 0.0)
CRUISE_Z = 40.0
FW = load_vehicle_type("aerosonde").fixed_wing
assert FW is not None
PARAMS = FW.params
# the landing: touchdown (first ground contact) within this far of the landing point, along
# the approach (the flare floats past it), and stopped on the runway line
TOUCHDOWN_WITHIN_M = 80.0
SETTLE_S = 15.0  # after a new leg starts (a turn of up to 180°), before "level"

MISSION = f"""
mission = [
  {{ x = 400.0, y = 0.0, z = {CRUISE_Z} }},
  {{ x = 400.0, y = 400.0, z = {CRUISE_Z} }},
  {{ x = -200.0, y = 400.0, z = {CRUISE_Z}, hold_s = 40.0 }},
  {{ x = -500.0, y = 0.0, z = 30.0 }},
  {{ command = "land", x = {LAND[0]}, y = {LAND[1]}, z = 0.0 }},
]
"""


@dataclass
class Flight:
    digest: str = ""
    states: list[VehicleState] = field(default_factory=list)
    index: list[int] = field(default_factory=list)
    modes: list[str] = field(default_factory=list)
    refusals: list[str] = field(default_factory=list)


def fly(scenario: Scenario, seconds: float = 190.0) -> Flight:
    out = Flight()
    h = hashlib.sha256()
    with FusedRunner(scenario, plume=False) as run:
        ap = run.flights["p"].autopilot
        assert run.command("p", Arm()).accepted
        assert run.command("p", MissionStart(start_index=0)).accepted
        for k in range(int(seconds * 120)):
            s = run.step(1)[0]
            h.update(repr(s).encode())
            st = ap.status()
            out.states.append(s)
            out.index.append(st.mission_index)
            out.modes.append(str(st.mode))
            if k == 30 * 120:  # mid-mission, on the first leg: below stall
                reply = run.command("p", Goto(position_enu_m=(0.0, 0.0, 40.0), speed_m_s=10.0))
                assert not reply.accepted
                out.refusals.append(reply.reason)
    out.digest = h.hexdigest()
    return out


@pytest.fixture(scope="module")
def flights() -> tuple[Flight, Flight]:
    sc = plane_scenario("crash_speed_m_s = 3.0", MISSION)
    return fly(sc), fly(sc)


def airspeed(s: VehicleState) -> float:
    vx, vy, vz = s.velocity_enu_m_s
    return math.sqrt((vx - WIND[0]) ** 2 + (vy - WIND[1]) ** 2 + (vz - WIND[2]) ** 2)


def test_two_runs_give_the_same_digest(flights: tuple[Flight, Flight]) -> None:
    a, b = flights
    assert a.digest == b.digest


def test_takes_off_flies_the_mission_and_lands_near_the_point(
    flights: tuple[Flight, Flight],
) -> None:
    f = flights[0]
    airborne = [i for i, s in enumerate(f.states) if s.position_enu_m[2] > 20.0]
    assert airborne, "never took off"
    first_air = airborne[0]
    # every waypoint reached in order, then the land item
    seen = sorted(set(f.index))
    assert seen == [0, 1, 2, 3, 4]
    touchdown = next(i for i in range(first_air, len(f.states)) if f.states[i].on_ground)
    x, y, _ = f.states[touchdown].position_enu_m
    assert math.hypot(x - LAND[0], y - LAND[1]) < TOUCHDOWN_WITHIN_M
    assert abs(y - LAND[1]) < 5.0  # on the approach line (from (-500, 0) through (0, 0))
    assert f.modes[-1] == "disarmed"
    last = f.states[-1]
    assert last.on_ground and math.hypot(*last.velocity_enu_m_s[:2]) < 1.0


def test_level_legs_hold_airspeed_and_altitude(flights: tuple[Flight, Flight]) -> None:
    f = flights[0]
    dt = 1.0 / 120.0
    start: dict[int, int] = {}
    worst_speed = worst_height = 0.0
    n = 0
    for i, (s, idx) in enumerate(zip(f.states, f.index, strict=True)):
        start.setdefault(idx, i)
        # legs 1 and 2 (to (400, 400) and the loiter around (-200, 400)) are at CRUISE_Z, as
        # their predecessors; the setpoint is FW_AIRSPD_TRIM (no item speed)
        if idx not in (1, 2) or (i - start[idx]) * dt < SETTLE_S:
            continue
        worst_speed = max(worst_speed, abs(airspeed(s) - PARAMS.fw_airspd_trim))
        worst_height = max(worst_height, abs(s.position_enu_m[2] - CRUISE_Z))
        n += 1
    assert n > 40 * 120  # the legs and the loiter: most of a minute of level flight
    assert worst_speed <= 1.0
    assert worst_height <= 2.0


def test_never_hits_the_ground_faster_than_its_crash_speed(
    flights: tuple[Flight, Flight],
) -> None:
    f = flights[0]
    assert not any(s.crashed for s in f.states)
    # the sink rate at each new ground contact, from the states (0.5 s before included)
    contacts = [
        i
        for i in range(1, len(f.states))
        if f.states[i].on_ground and not f.states[i - 1].on_ground
    ]
    assert contacts
    for i in contacts:
        sink = max(-s.velocity_enu_m_s[2] for s in f.states[max(0, i - 60) : i + 1])
        assert sink < 3.0


def test_a_below_stall_goto_is_refused_and_the_mission_goes_on(
    flights: tuple[Flight, Flight],
) -> None:
    f = flights[0]
    assert len(f.refusals) == 1
    assert "FW_AIRSPD_MIN 18" in f.refusals[0] and "stall" in f.refusals[0]
    assert f.modes[30 * 120 + 1] == "mission"
    # no tick of the flight below the stall speed in the air (15.3 m/s level, table E.2)
    in_air = [s for s in f.states if s.position_enu_m[2] > 5.0]
    assert min(airspeed(s) for s in in_air) > 16.0


def test_a_mission_item_below_stall_is_refused_at_upload() -> None:
    sc = plane_scenario("crash_speed_m_s = 3.0", MISSION)
    with FusedRunner(sc, plume=False) as run:
        item = MissionItem(x=100.0, y=0.0, z=30.0, speed_m_s=12.0)
        reply = run.command("p", MissionUpload(items=[item]))
        assert not reply.accepted
        assert "item 0: speed_m_s 12 m/s is below FW_AIRSPD_MIN" in reply.reason
        assert run.flights["p"].autopilot.kind == "fixed_wing"
