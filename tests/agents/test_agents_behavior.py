"""Behaviour plug-ins: loading, and the casting example finding its way up the plume."""

from __future__ import annotations

import math

import msgspec
import pytest

from agents.autopilot import Autopilot
from agents.behavior import BehaviorError
from agents.build import AutopilotOptions, build_autopilot
from plume_service import GaussianPlume
from swarmbus.messages import Arm, FlightMode, SetMode, Takeoff
from swarmbus.scenario import Scenario, load_scenario
from tests.support.toy_physics import ToyWorld

CASTING = "agents.behaviors.casting:Casting"
SOURCE = (0.0, 0.0, 10.0)


def casting_scenario(spawn: tuple[float, float, float]) -> Scenario:
    sc = load_scenario()
    v = msgspec.structs.replace(sc.vehicles[0], spawn_enu_m=spawn, mission=[], behavior=CASTING)
    return msgspec.structs.replace(sc, vehicles=[v])


def test_casting_ends_closer_to_the_source_than_it_started() -> None:
    sc = casting_scenario((45.0, 6.0, 0.0))
    ap = build_autopilot(sc, "uav1", AutopilotOptions())
    w = ToyWorld(sc, {"uav1": ap}, field=GaussianPlume.preset("novak2018").concentration)
    w.run(0.05)
    for cmd in (Arm(), Takeoff(altitude_m=10.0)):
        assert ap.handle(cmd).accepted
    w.run(20.0, until=lambda: ap.modes.mode == FlightMode.HOLD)
    start = math.dist(w.vehicles["uav1"].p, SOURCE)
    reply = ap.handle(SetMode(mode=FlightMode.OFFBOARD))
    assert reply.accepted, reply.reason
    w.run(90.0)
    end = math.dist(w.vehicles["uav1"].p, SOURCE)
    assert ap.modes.mode == FlightMode.OFFBOARD
    assert any(r.reported_g_m3 for r in w.readings["uav1"])  # it found the plume
    assert end < 0.5 * start, (start, end)


def test_bad_behaviour_spec_is_a_clear_error() -> None:
    sc = casting_scenario((0.0, 0.0, 0.0))
    bad = msgspec.structs.replace(sc.vehicles[0], behavior="agents.behaviors.casting:Nope")
    sc = msgspec.structs.replace(sc, vehicles=[bad])
    with pytest.raises(BehaviorError, match="Nope"):
        build_autopilot(sc, "uav1", AutopilotOptions())


class Exploding:
    def __init__(self, ctx: object) -> None:
        pass

    def step(self, *args: object) -> None:
        raise RuntimeError("boom")


def test_a_failing_behaviour_triggers_the_offboard_loss_action_not_a_crash() -> None:
    sc = casting_scenario((20.0, 0.0, 0.0))
    ap = Autopilot(sc, "uav1", behavior=Exploding(None))
    w = ToyWorld(sc, {"uav1": ap})
    w.run(0.05)
    ap.handle(Arm())
    ap.handle(Takeoff(altitude_m=3.0))
    w.run(10.0, until=lambda: ap.modes.mode == FlightMode.HOLD)
    assert ap.handle(SetMode(mode=FlightMode.OFFBOARD)).accepted
    w.run(0.1)
    assert ap.modes.mode == FlightMode.HOLD  # failsafe.offboard_loss_action
    assert "boom" in ap.status().health
