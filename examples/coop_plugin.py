"""A cooperative source-seeking behaviour written outside plumeswarm, put through the swarm
table of ``bench gsl`` (docs/swarm.md, "Your own cooperative behaviour").

``SharedBest``: every member keeps the strongest reading it has taken and publishes it over
the radio (``ctx.mailbox.publish``, one ``BestReading`` of 28 bytes) whenever it improves; a
member that hears a peer's better reading adopts it. With no reading yet, a member sweeps
crosswind (left or right first by its index) while drifting upwind; once the swarm has a best
reading, it flies to a point ``upwind_bias_m`` upwind of it and sweeps crosswind there, so
the swarm climbs the plume toward the source. It declares the swarm's best reading once the
best has not improved for ``give_up_s``. Its tunables are class attributes.

Run it through the swarm table (from the repository root, so that ``examples.coop_plugin``
is importable)::

    PYTHONPATH=. plumeswarm bench gsl --algorithms mine=examples.coop_plugin:SharedBest \\
        --environments steady_gaussian --sensors ideal --runs 3 --vehicles 1,3 --out runs/mine

or register it in your own package's ``pyproject.toml``::

    [project.entry-points."plumeswarm.behaviors"]
    shared_best = "examples.coop_plugin:SharedBest"

and name it: ``plumeswarm bench gsl --algorithms shared_best --vehicles 1,3``.
"""

from __future__ import annotations

from typing import ClassVar

import msgspec

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.detection import valid_values
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import fly, toward
from swarmbus.messages import Setpoint


class BestReading(msgspec.Struct, frozen=True, array_like=True):
    """A member's strongest reading so far: where (ENU m) and how much (g/m³)."""

    x_m: float
    y_m: float
    g_m3: float


class SharedBest(SeekingBehavior):
    """Members share their best reading and fly toward the swarm's best, upwind-biased."""

    vehicles = 3  # how many vehicles the bench flies it on without --vehicles
    source = "example: shared best reading, upwind-biased"
    talks: ClassVar[bool] = True  # it needs a runner that carries behaviour messages
    start_spacing_m = 4.0  # the bench starts the members on a crosswind line this far apart
    own_state = ("best", "improved_s", "side", "anchor_across_m")  # kept over restarts
    # tunables (``bench gsl sweep behavior.give_up_s=10,20,40`` varies one)
    speed_m_s, upwind_bias_m, sweep_half_width_m, give_up_s = 2.0, 3.0, 6.0, 20.0

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.best: tuple[float, float, float] | None = None  # x, y, g/m³: the swarm's best
        self.improved_s = 0.0  # when the best last improved
        self.side = 1.0 if ctx.vehicle_index % 2 == 0 else -1.0
        self.anchor_across_m: float | None = None

    def seek(self, step: SeekStep) -> Setpoint | None:
        own, frame = step.own, step.wind.frame
        now = own.sim_time_s
        improved = False
        for x, y, value in valid_values(step.readings):
            improved = (value > 0.0 and self._adopt(x, y, value, now)) or improved
        if improved and self.best is not None and self.mailbox is not None:
            self.mailbox.publish(BestReading(x_m=self.best[0], y_m=self.best[1], g_m3=self.best[2]))
        for received in step.inbox:
            message = received.message
            if isinstance(message, BestReading):
                self._adopt(message.x_m, message.y_m, message.g_m3, now)
        if self.best is not None and now - self.improved_s > self.give_up_s:
            self.declaration = SourceEstimate(self.best[0], self.best[1], now)
            return None  # the base holds over the declaration
        along, across = frame.coordinates(own.position_enu_m[0], own.position_enu_m[1])
        if self.best is not None:
            best_along, best_across = frame.coordinates(self.best[0], self.best[1])
            aim_along = best_along - self.upwind_bias_m
            if along > aim_along + 1.0:  # downwind of the aim point: go there first
                x, y = frame.velocity(aim_along, best_across)  # the same map: a point
                return fly(own, toward(own, x, y, self.speed_m_s), self.altitude)
            self.anchor_across_m = best_across
        elif self.anchor_across_m is None:
            self.anchor_across_m = across
        if abs(across - self.anchor_across_m) > self.sweep_half_width_m:
            self.side = -1.0 if across > self.anchor_across_m else 1.0
        drift = 0.0 if self.best is not None else -0.3 * self.speed_m_s  # upwind until gas
        return fly(own, frame.velocity(drift, self.side * self.speed_m_s), self.altitude)

    def _adopt(self, x_m: float, y_m: float, g_m3: float, now: float) -> bool:
        """Take (x, y, g) as the best if it is better; whether it was."""
        if self.best is not None and g_m3 <= self.best[2]:
            return False
        self.best = (x_m, y_m, g_m3)
        self.improved_s = now
        return True
