"""Cooperative declaration: surge-cast searchers that share detections and pool their empty casts.

The members fly cooperative surge-cast (:mod:`agents.behaviors.coop_surge_cast`: Lochmatter &
Martinoli 2008, detections shared over the radio) and also share the evidence of the
declaration. Surge-cast declares the source once a cast on the line just upwind of the
most upwind detection (the frontier) has flown ``empty_legs`` (8) legs without a detection
(:mod:`agents.behaviors.tracking`): eight crossings of the plume's thread, each missing it
with a probability ≤ 0.48, so that all eight miss with ≤ 0.3 %. Crossings by different
members are the same evidence, so the swarm pools them, as a group of moths would if each
told the others where it had searched (the collective olfactory search of Durve, Piro,
Cencini, Biferale & Celani 2020, Phys. Rev. E 102:012402, blends each agent's private
detections with public information from the others; here the public information is the
peers' detections and their empty legs):

- at every turn of its cast a member publishes one :class:`CastLegs` (the ENU point of its
  cast line at the frontier, the time of the last detection it knew when it began the cast,
  and its legs on that line so far; 32 bytes of msgpack);
- a member's cast is empty when its own legs plus the legs of the peers whose latest report
  is on the same line (within ``same_line_m`` of its own line's point) and no older than its
  own last detection reach ``empty_legs``, it has itself flown at least ``own_legs_min``
  legs, and the blank and detection-count conditions of surge-cast hold. It then declares
  between the frontier and the line, as surge-cast does.

With one vehicle it is surge-cast: nothing to pool. Parameters (``same_line_m`` 3 m: the
cluster width of the frontier; ``own_legs_min`` 2: each member's first two legs reach
3 m and 4.8 m either side of its anchor) — tuned on seeds ≥ 1000 only (docs/gsl.md).
Use ``behavior = "agents.behaviors.coop_declare:CooperativeDeclaration"`` on every member.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import ClassVar

import msgspec

from agents.behavior import BehaviorContext
from agents.behaviors.coop_surge_cast import CooperativeSurgeCast
from agents.behaviors.seeking import SeekStep
from agents.behaviors.tracking import PlumeTracker
from swarmbus.messages import Setpoint


class CastLegs(msgspec.Struct, frozen=True, array_like=True):
    """A member's cast: its line's ENU point at the frontier, the last detection it knew when
    the cast began (sim time), and the legs it has flown on that line."""

    x_m: float
    y_m: float
    since_s: float
    legs: int


@dataclass
class PooledTracker(PlumeTracker):
    """A :class:`PlumeTracker` whose cast counts the peers' legs on the same line."""

    state_attributes: ClassVar[tuple[str, ...]] = (*PlumeTracker.state_attributes, "peer_casts")

    same_line_m: float = 3.0
    own_legs_min: int = 2
    #: The latest :class:`CastLegs` of each peer, as (x, y, since_s, legs).
    peer_casts: dict[str, tuple[float, float, float, int]] = field(default_factory=dict, init=False)

    def line_point(self) -> tuple[float, float] | None:
        """The ENU point of the current cast line at the frontier (None when not casting)."""
        front = self.frontier()
        if self.state != "cast" or self.cast_line is None or front is None:
            return None
        return self.wind.mean().velocity(self.cast_line[1], front[1])

    def own_legs(self) -> int:
        return 0 if self.cast_line is None else self.cast.legs - self.cast_line[0]

    def pooled_legs(self) -> int:
        """Own legs on the line plus the peers' on the same line since the last detection."""
        own = self.own_legs()
        point = self.line_point()
        if point is None or self.last_hit_s is None:
            return own
        peers = sum(
            legs
            for x, y, since, legs in self.peer_casts.values()
            if since >= self.last_hit_s and math.dist((x, y), point) <= self.same_line_m
        )
        return own + peers

    def _empty(self, now_s: float) -> bool:
        assert self.cast_line is not None and self.last_hit_s is not None
        blank = now_s - self.last_hit_s
        return (
            self.own_legs() >= self.own_legs_min
            and self.pooled_legs() >= self.empty_legs
            and blank >= self.blank_factor * self.longest_blank_s
            and len(self.hits) >= self.min_hits
        )


class CooperativeDeclaration(CooperativeSurgeCast):
    vehicles = 3
    source = (
        "Lochmatter & Martinoli 2008 surge-cast; detections and empty casts pooled over the "
        "radio (private and public information, Durve et al. 2020)"
    )
    talks: ClassVar[bool] = True
    own_state: ClassVar[tuple[str, ...]] = (*CooperativeSurgeCast.own_state, "reported_legs")
    start_spacing_m = 4.0
    same_line_m = 3.0
    own_legs_min = 2

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        old = self.tracker
        self.tracker = PooledTracker(
            old.cast, same_line_m=self.same_line_m, own_legs_min=self.own_legs_min
        )
        self.reported_legs = 0

    def seek(self, step: SeekStep) -> Setpoint | None:
        tracker = self.tracker
        assert isinstance(tracker, PooledTracker)
        for received in sorted(step.inbox, key=lambda r: (r.sent_tick, r.sender)):
            m = received.message
            if isinstance(m, CastLegs):
                tracker.peer_casts[received.sender] = (m.x_m, m.y_m, m.since_s, m.legs)
        setpoint = super().seek(step)
        legs = tracker.own_legs() if tracker.state == "cast" else 0
        point = tracker.line_point()
        if self.mailbox is not None and point is not None and legs > self.reported_legs:
            assert tracker.last_hit_s is not None
            self.mailbox.publish(
                CastLegs(x_m=point[0], y_m=point[1], since_s=tracker.last_hit_s, legs=legs)
            )
        self.reported_legs = legs
        return setpoint
