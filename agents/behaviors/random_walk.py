"""Random walk: the uninformed baseline every source-seeking result is compared with.

A run-and-tumble (correlated) random walk, the standard null model of search (Codling, Plank &
Benhamou 2008, "Random walk models in biology", J. R. Soc. Interface 5:813): fly straight at
``speed_m_s`` on a heading drawn uniformly, and tumble to a new uniform heading at the times of
a Poisson process with mean run time ``mean_run_s`` (per control tick with probability
1 − exp(−dt/mean_run_s)). Its mean squared displacement is
MSD(t) = 2v²τ²(t/τ − 1 + e^(−t/τ)) with τ = ``mean_run_s``. It ignores the sensor and the
wind, never declares a source, and holds the altitude it starts at (the seeking base's
preamble, :class:`agents.behaviors.seeking.SeekingBehavior`). The headings come from the
context's seeded generator, so a run repeats exactly.

Use ``behavior = "agents.behaviors.random_walk:RandomWalk"``.
"""

from __future__ import annotations

import math

from agents.behavior import BehaviorContext
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import fly
from swarmbus.messages import Setpoint, VehicleState


def _calm(own: VehicleState) -> tuple[float, float]:
    return 0.0, 0.0


class RandomWalk(SeekingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    # ``rng`` is the context's generator, which the autopilot saves on its own
    own_state = ("heading_rad",)
    speed_m_s = 2.0
    mean_run_s = 5.0

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.read_wind = _calm  # it ignores the wind: no anemometer read every step
        self.rng = ctx.rng
        self.tumble_probability = 1.0 - math.exp(-ctx.control_dt_s / self.mean_run_s)
        self.heading_rad = float(self.rng.uniform(0.0, 2.0 * math.pi))

    def seek(self, step: SeekStep) -> Setpoint | None:
        own = step.own
        if self.rng.random() < self.tumble_probability:
            self.heading_rad = float(self.rng.uniform(0.0, 2.0 * math.pi))
        v = self.speed_m_s
        return fly(
            own, (v * math.cos(self.heading_rad), v * math.sin(self.heading_rad)), self.altitude
        )
