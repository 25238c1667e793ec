"""Oracle: flies straight to the true source and declares it — the ceiling of every table.

It knows what no searcher knows: the source's position, the scenario's first
``[[plume.sources]]`` entry (``ctx.scenario.plume.sources[0]``), and ignores the sensor. It flies
toward the source horizontally at ``speed_m_s`` (the searchers' surge speed) at the altitude it
starts at and declares the source once within ``arrive_m`` of it, at the true position. Its
time and path to the source are the shortest a searcher flying at that speed can have from the
same start; its success rate is the ceiling (1 unless the time limit is too short for the
distance).

Use ``behavior = "agents.behaviors.oracle:Oracle"``.
"""

from __future__ import annotations

import math

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import fly, toward
from swarmbus.messages import Setpoint


class Oracle(SeekingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    own_state = ()
    vehicles = 1
    source = "knows the source (ceiling)"
    speed_m_s = 2.0
    arrive_m = 0.5

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        source = ctx.scenario.plume.sources[0]
        self.source_xy = (source.x_m, source.y_m)

    def seek(self, step: SeekStep) -> Setpoint | None:
        own = step.own
        sx, sy = self.source_xy
        x, y, _ = own.position_enu_m
        if math.hypot(sx - x, sy - y) <= self.arrive_m:
            self.declaration = SourceEstimate(x_m=sx, y_m=sy, sim_time_s=own.sim_time_s)
            return None
        return fly(own, toward(own, sx, sy, self.speed_m_s), self.altitude)
