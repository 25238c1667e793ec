"""Cooperative surge-cast: a member surges on a peer's detection and publishes its own (the
autopilot process's refusal: tests/agents/test_peer_link.py)."""

from __future__ import annotations

import msgspec
import numpy as np
import pytest

from agents.behavior import BehaviorContext
from agents.behaviors.coop_surge_cast import CooperativeSurgeCast, Detection
from agents.peer_link import PeerLink, Received
from swarmbus.messages import Setpoint, VehicleState
from swarmbus.scenario import Sensor, VehicleSpec, load_scenario
from tests.support.messages_samples import reading, vehicle_state

SCENARIO = load_scenario()  # wind 6 m/s toward +x
IDEAL = msgspec.structs.replace(
    SCENARIO,
    sensor=Sensor(preset="ideal"),
    anemometer=msgspec.structs.replace(SCENARIO.anemometer, noise_std_m_s=0.0),
    vehicles=[VehicleSpec(id=v) for v in ("uav1", "uav2")],
)


def member(index: int = 0) -> tuple[CooperativeSurgeCast, PeerLink]:
    link = PeerLink(IDEAL)
    vid = f"uav{index + 1}"
    rng = np.random.Generator(np.random.PCG64(1))
    ctx = BehaviorContext(vid, index, IDEAL, 0.05, rng, link.mailboxes[vid])
    return CooperativeSurgeCast(ctx), link


def velocity(sp: Setpoint | None) -> tuple[float, float, float]:
    assert sp is not None and sp.velocity_enu_m_s is not None
    return sp.velocity_enu_m_s


def state(x: float, y: float, t: float) -> VehicleState:
    return vehicle_state("uav1", 0, (x, y, 10.0), sim_time_s=t, lat_deg=0.0, lon_deg=0.0)


def test_a_peers_detection_starts_a_surge_and_joins_the_frontier() -> None:
    beh, link = member()
    box = link.mailboxes["uav1"]
    beh.step(state(50.0, 5.0, 0.0), [], [])
    assert beh.tracker.state == "search"
    box.inbox = [Received("uav2", 19, Detection(x_m=48.0, y_m=-3.0, sim_time_s=0.95))]
    sp = beh.step(state(50.0, 5.0, 1.0), [], [reading("uav1", 1.0, (50.0, 5.0, 10.0), 0.0)])
    assert beh.tracker.state == "surge"
    assert velocity(sp)[:2] == pytest.approx((-2.0, 0.0))  # straight upwind
    assert beh.tracker.hits == [(48.0, -3.0)]
    assert box.outbox == []  # a peer's detection is not published again
    # an older detection arriving late does not move the hit memory back
    box.inbox = [Received("uav2", 5, Detection(x_m=49.0, y_m=-3.0, sim_time_s=0.25))]
    beh.step(state(49.9, 5.0, 1.05), [], [])
    assert beh.tracker.last_hit_s == 0.95
    assert beh.tracker.hits == [(48.0, -3.0), (49.0, -3.0)]
    # without detections the hit memory runs out 2 s after the peer's
    box.inbox = []
    beh.step(state(46.0, 5.0, 2.9), [], [])
    assert beh.tracker.state == "surge"
    beh.step(state(45.9, 5.0, 3.0), [], [])
    assert beh.tracker.state == "back"


def test_an_own_detection_is_published_once_per_step() -> None:
    beh, link = member()
    box = link.mailboxes["uav1"]
    beh.step(state(50.0, 5.0, 0.0), [], [])
    hits = [reading("uav1", 0.05, (50.0, 5.0, 10.0), 0.002), reading("uav1", 0.1, (49.9, 5.0,
            10.0), 0.003)]  # fmt: skip
    beh.step(state(49.9, 5.0, 0.1), [], hits)
    assert box.outbox == [Detection(x_m=49.9, y_m=5.0, sim_time_s=0.1)]
    assert len(msgspec.msgpack.encode(box.outbox[0])) <= 28


def test_without_a_mailbox_it_flies_surge_cast_alone() -> None:
    rng = np.random.Generator(np.random.PCG64(1))
    beh = CooperativeSurgeCast(BehaviorContext("uav1", 0, IDEAL, 0.05, rng))
    beh.step(state(50.0, 5.0, 0.0), [], [])
    beh.step(state(50.0, 5.0, 0.05), [], [reading("uav1", 0.05, (50.0, 5.0, 10.0), 0.002)])
    assert beh.tracker.state == "surge"
