"""Oracle: the ceiling every source-seeking result is compared with.

It is told where the source is — the first release point of the scenario's plume
(``[[plume.sources]]``), which no other behaviour reads — flies straight to it at
``speed_m_s`` and declares it once within ``arrival_radius_m``. Its success rate, time and
path bound what any strategy flying at the same speed can reach on the same starts.

Use ``behavior = "agents.behaviors.oracle:Oracle"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behaviors.search import SavesState, SourceEstimate, fly, start_or_hold, toward
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState


class Oracle(SavesState):
    state_attributes = ("altitude_m", "declaration")
    vehicles = 1
    source = "knows the source (ceiling)"
    speed_m_s = 2.0
    arrival_radius_m = 0.5

    def __init__(self, ctx: BehaviorContext) -> None:
        src = ctx.scenario.plume.sources[0]
        self.source_xy = (src.x_m, src.y_m)
        self.altitude_m: float | None = None
        self.declaration: SourceEstimate | None = None

    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None:
        self.altitude_m, hold = start_or_hold(own, self.altitude_m, self.declaration)
        if hold is not None:
            return hold
        x, y = self.source_xy
        if math.dist(own.position_enu_m[:2], (x, y)) <= self.arrival_radius_m:
            self.declaration = SourceEstimate(x, y, own.sim_time_s)
            return start_or_hold(own, self.altitude_m, self.declaration)[1]
        return fly(own, toward(own, x, y, self.speed_m_s), self.altitude_m)
