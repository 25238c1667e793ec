"""Cooperative declaration: the peers' empty legs on the same cast line count toward the
declaration; legs on another line, or from before the last detection, do not."""

from __future__ import annotations

import msgspec
import numpy as np

from agents.behavior import BehaviorContext
from agents.behaviors.coop_declare import CastLegs, CooperativeDeclaration, PooledTracker
from agents.peer_link import PeerLink, Received
from swarmbus.messages import ConcentrationReading
from tests.agents.test_coop_surge_cast import IDEAL, state
from tests.support.messages_samples import reading

DT = 0.05


def fly_to_cast(beh: CooperativeDeclaration) -> tuple[float, float, float]:
    """Ten detections while surging upwind (toward −x) from (50, 0), then none until the
    member casts on its line; its position and time then."""
    x, y, t = 50.0, 0.0, 0.0
    for k in range(400):
        hits: list[ConcentrationReading] = []
        if k < 10:
            hits = [reading("uav1", t, (x, y, 10.0), 0.01)]
        sp = beh.step(state(x, y, t), [], hits)
        assert sp is not None and sp.velocity_enu_m_s is not None
        x += sp.velocity_enu_m_s[0] * DT
        y += sp.velocity_enu_m_s[1] * DT
        t += DT
        if beh.tracker.state == "cast":
            return x, y, t
    raise AssertionError("never cast")


def member() -> tuple[CooperativeDeclaration, PeerLink]:
    link = PeerLink(IDEAL)
    rng = np.random.Generator(np.random.PCG64(1))
    ctx = BehaviorContext("uav1", 0, IDEAL, DT, rng, link.mailboxes["uav1"])
    return CooperativeDeclaration(ctx), link


def legs_at_declaration(peer: CastLegs | None, shift_m: float = 0.0) -> tuple[int, int]:
    """Fly to the cast; give ``peer`` (its line point relative to the member's own, shifted
    ``shift_m`` crosswind) at every step; the member's own legs when it declares, and how
    many CastLegs it published during the cast."""
    beh, link = member()
    box = link.mailboxes["uav1"]
    x, y, t = fly_to_cast(beh)
    tracker = beh.tracker
    assert isinstance(tracker, PooledTracker)
    published = 0
    for _ in range(4000):
        point = tracker.line_point()
        assert point is not None
        box.inbox = []
        if peer is not None:
            message = msgspec.structs.replace(peer, x_m=point[0], y_m=point[1] + shift_m)
            box.inbox = [Received("uav2", 0, message)]
        published += sum(isinstance(m, CastLegs) for m in box.outbox)
        box.outbox = []
        sp = beh.step(state(x, y, t), [], [])
        if beh.declaration is not None:
            return tracker.own_legs(), published + sum(isinstance(m, CastLegs) for m in box.outbox)
        assert sp is not None and sp.velocity_enu_m_s is not None
        x += sp.velocity_enu_m_s[0] * DT
        y += sp.velocity_enu_m_s[1] * DT
        t += DT
    raise AssertionError("never declared")


def test_alone_it_declares_after_eight_empty_legs_as_surge_cast() -> None:
    own, published = legs_at_declaration(None)
    assert own == 8
    assert published == 8  # one report at every turn


def test_a_peers_six_legs_on_the_same_line_cut_the_cast_to_two() -> None:
    last_hit_s = 9 * DT  # the tenth detection, at step 9
    assert legs_at_declaration(CastLegs(0.0, 0.0, last_hit_s, 6))[0] == 2
    assert legs_at_declaration(CastLegs(0.0, 0.0, last_hit_s, 3), shift_m=2.5)[0] == 5
    # a report from another line, or about legs flown before the last detection: not counted
    assert legs_at_declaration(CastLegs(0.0, 0.0, last_hit_s, 6), shift_m=10.0)[0] == 8
    assert legs_at_declaration(CastLegs(0.0, 0.0, last_hit_s - 0.1, 6))[0] == 8
