"""Cooperative surge-cast: surge-cast searchers that share their detections over the radio.

Each member flies surge-cast (:class:`~agents.behaviors.surge_cast.SurgeCast`, Lochmatter &
Martinoli 2008, with the tracking, casting and declaration of
:mod:`agents.behaviors.tracking`) and publishes, in each step in which it detected gas, one
:class:`Detection` (where and when, 28 bytes of msgpack) to its peers (``ctx.mailbox``,
docs/agents.md "The radio between vehicles"). A peer's detection counts as the member's own
for the plume's position — it joins the detections the frontier and the declaration are made
of — and it restarts the surge (the hit memory runs from the peer's detection time); the
longest blank the declaration waits for is then the swarm's, between two detections of any
member. So the swarm surges as one sensor spread over its members, shares one frontier (the
most upwind detection any member made), and each member casts its own side of it (the first
sweep to the left on an even index, to the right on an odd one).

Detections that the radio loses or delays arrive late or not at all; one older than the
member's last hit does not move the hit memory back. Where the runner carries no peer
messages (``ctx.mailbox`` is ``None``) the member flies surge-cast alone. Use ``behavior =
"agents.behaviors.coop_surge_cast:CooperativeSurgeCast"`` on every member.
"""

from __future__ import annotations

from typing import ClassVar

import msgspec

from agents.behaviors.seeking import SeekStep
from agents.behaviors.surge_cast import SurgeCast
from swarmbus.messages import Setpoint


class Detection(msgspec.Struct, frozen=True, array_like=True):
    """A member's detection: ENU metres and sim time (the last of its step)."""

    x_m: float
    y_m: float
    sim_time_s: float


class CooperativeSurgeCast(SurgeCast):
    vehicles = 3
    source = "Lochmatter & Martinoli 2008; detections shared over the radio"
    talks: ClassVar[bool] = True
    start_spacing_m = 4.0  # the bench starts the members on a crosswind line this far apart

    def seek(self, step: SeekStep) -> Setpoint | None:
        tracker = self.tracker
        for received in sorted(step.inbox, key=lambda r: (r.sent_tick, r.sender)):
            message = received.message
            if isinstance(message, Detection):
                tracker.hits.append((message.x_m, message.y_m))
                last = tracker.last_hit_s
                if last is None or message.sim_time_s > last:
                    tracker.last_hit_s = message.sim_time_s
                    tracker.cast_frame = tracker.wind.average
        shared = len(tracker.hits)
        setpoint = super().seek(step)
        if self.mailbox is not None and len(tracker.hits) > shared:
            x, y = tracker.hits[-1]
            assert tracker.last_hit_s is not None
            self.mailbox.publish(Detection(x_m=x, y_m=y, sim_time_s=tracker.last_hit_s))
        return setpoint
