"""A restarted autopilot takes its vehicle back: found in the air (not crashed) it arms itself
and holds where it is; found on the ground it stays disarmed. The autopilot's pure logic flown
against the toy dynamics (the process-level kill under ``plumeswarm up`` is in
test_faults_stack.py)."""

from __future__ import annotations

import math

from agents.autopilot import Autopilot
from swarmbus.messages import Arm, FlightMode, Takeoff
from swarmbus.scenario import load_scenario
from tests.support.toy_physics import ToyWorld


def test_restarted_in_the_air_holds_where_it_is() -> None:
    sc = load_scenario()
    aps = {"uav1": Autopilot(sc, "uav1")}
    w = ToyWorld(sc, aps)
    w.run(0.05)
    assert aps["uav1"].handle(Arm()).accepted
    assert aps["uav1"].handle(Takeoff(altitude_m=12.0)).accepted
    w.run(20.0, until=lambda: aps["uav1"].modes.mode == FlightMode.HOLD)
    w.run(3.0)
    before = w.vehicles["uav1"].p.copy()
    fresh = Autopilot(sc, "uav1")  # the supervisor's restart: a new process, no memory
    w.autopilots["uav1"] = fresh
    w.run(10.0)
    after = w.vehicles["uav1"].p
    assert fresh.modes.armed and fresh.modes.mode == FlightMode.HOLD
    assert not w.vehicles["uav1"].crashed
    assert math.dist(before, after) < 1.0, (before, after)
    assert "restarted in the air" in fresh.status().failsafe


def test_restarted_on_the_ground_stays_disarmed() -> None:
    sc = load_scenario()
    aps = {"uav1": Autopilot(sc, "uav1")}
    w = ToyWorld(sc, aps)
    w.run(0.5)
    fresh = Autopilot(sc, "uav1")
    w.autopilots["uav1"] = fresh
    w.run(2.0)
    assert fresh.modes.mode == FlightMode.DISARMED
    assert w.vehicles["uav1"].on_ground


def test_the_vehicle_state_lost_in_the_air_lands_and_keeps_landing_when_it_returns() -> None:
    """Realtime mode, the ticks stopped (a link to the physics down): the autopilot lands, says
    why, and keeps landing once the states come back (PX4 stays in its failsafe mode)."""
    sc = load_scenario()
    ap = Autopilot(sc, "uav1")
    w = ToyWorld(sc, {"uav1": ap})
    w.run(0.05)
    assert ap.handle(Arm()).accepted and ap.handle(Takeoff(altitude_m=12.0)).accepted
    w.run(20.0, until=lambda: ap.modes.mode == FlightMode.HOLD)
    ap.state_lost(2.0)
    assert ap.modes.mode == FlightMode.LAND
    assert ap.status().failsafe == "vehicle state lost: no tick for 2.0 s"
    w.run(30.0, until=lambda: not ap.modes.armed)
    assert not ap.modes.armed and w.vehicles["uav1"].on_ground and not w.vehicles["uav1"].crashed


def test_the_vehicle_state_lost_on_the_ground_changes_nothing() -> None:
    sc = load_scenario()
    ap = Autopilot(sc, "uav1")
    w = ToyWorld(sc, {"uav1": ap})
    w.run(0.5)
    ap.state_lost(3.0)
    assert ap.modes.mode == FlightMode.DISARMED and ap.status().failsafe == ""
