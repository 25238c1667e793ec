"""Cross-wind casting: find the plume, climb its concentration gradient toward the source.

The moth strategy (Kennedy & Marsh 1974, Science 184:999; as a robot algorithm, e.g. Ishida et
al. 1994 and Lochmatter & Martinoli 2008). While the sensor detects gas (a reading of at least
:data:`~agents.behaviors.detection.PLUME_THRESHOLD_G_M3`; with a lagging sensor such as the PID
and metal-oxide presets: a rise of the equivalent,
:func:`~agents.behaviors.detection.detector_for`) and for the hit memory after it, the vehicle
*surges* upwind, weaving cross-wind and turning back whenever the reading drops below
``turn_fraction`` of the best of the leg (climbing the cross-wind gradient, which keeps it on
the plume's axis). When the gas is lost it *casts*: cross-wind legs of growing width centred on
where it last smelled gas, without drifting.

The hit memory, the averaged wind, the cast and the stopping rule — the source declared
between the most upwind detection and the cast line just upwind of it once the cast along
that line has flown ``empty_legs`` (8) legs without a detection — are those of surge-cast
(:class:`~agents.behaviors.tracking.PlumeTracker`, where each number and the plume statistic
it comes from are).

Use it with ``behavior = "agents.behaviors.casting:Casting"`` on a vehicle and switch that
vehicle to offboard mode once it flies (the behaviour holds the altitude it starts at).
"""

from __future__ import annotations

from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behaviors.tracking import TrackingBehavior
from swarmbus.messages import ConcentrationReading


class Casting(TrackingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    own_state = ("detector", "tracker", "track_altitude_m", "side", "leg_best")
    surge_speed_m_s = 2.0
    weave_speed_m_s = 0.3
    cast_speed_m_s = 2.5
    first_cast_half_width_m = 4.0
    cast_growth = 1.5
    max_cast_half_width_m = 20.0
    turn_fraction = 0.9

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.side = self.tracker.cast.side  # the weave starts on the side the first sweep does
        self.leg_best = 0.0  # best reading since the last turn

    def observe(self, readings: Sequence[ConcentrationReading]) -> None:
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            value = r.reported_g_m3
            if self.detector.hit(value):
                if value < self.turn_fraction * self.leg_best:  # going down the gradient: turn
                    self.side = -self.side
                    self.leg_best = value
                self.leg_best = max(self.leg_best, value)
                self.record(r)
            else:
                self.leg_best = 0.0

    def surge_across_m_s(self) -> float:
        """Weaving across the plume's axis."""
        return self.weave_speed_m_s * self.side
