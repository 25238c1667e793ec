"""A source-seeking behaviour written outside plumeswarm, benchmarked with ``bench gsl``.

Upwind surge on any gas, crosswind zigzag without: the smallest useful strategy. On
``SeekingBehavior``, which reads the wind from the anemometer, keeps the altitude and holds
after a declaration, it detects gas with the sensor-aware detector and declares the strongest
reading once it has flown ``give_up_s`` without a new best. Its tunables are class
attributes, so ``bench gsl sweep behavior.zigzag_half_width_m=5,10`` varies them.

Run it next to the built-ins (from the repository root)::

    PYTHONPATH=examples plumeswarm bench gsl --algorithms mine=my_behavior:UpwindZigzag,casting \\
        --environments steady_gaussian --sensors ideal --runs 3 --out runs/mine

or register it in your own package's ``pyproject.toml``::

    [project.entry-points."plumeswarm.behaviors"]
    upwind_zigzag = "my_behavior:UpwindZigzag"

and name it: ``plumeswarm bench gsl --algorithms upwind_zigzag``.
"""

from __future__ import annotations

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.detection import detector_for, valid_values
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import fly
from swarmbus.messages import Setpoint


class UpwindZigzag(SeekingBehavior):
    """The base (:class:`~agents.behaviors.seeking.SeekingBehavior`) keeps the altitude, reads
    the wind and holds once ``self.declaration`` is set; :meth:`seek` decides the rest."""

    vehicles = 1  # how many vehicles the bench flies it on
    source = "example: upwind surge, crosswind zigzag"
    own_state = ("detector", "best", "side", "origin_across_m")  # kept over autopilot restarts
    speed_m_s = 2.0
    zigzag_half_width_m = 8.0
    give_up_s = 20.0

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.detector = detector_for(ctx)
        self.best: tuple[float, float, float, float] | None = None  # x, y, value, time
        self.side = 1.0
        self.origin_across_m: float | None = None

    def seek(self, step: SeekStep) -> Setpoint | None:
        own, readings = step.own, step.readings
        now = own.sim_time_s
        values = valid_values(readings)
        for x, y, value in values:
            if self.best is None or value > self.best[2]:
                self.best = (x, y, value, now)
        if self.best is not None and now - self.best[3] > self.give_up_s:
            self.declaration = SourceEstimate(self.best[0], self.best[1], now)
            return None  # the base holds over the declaration
        we, wn = step.wind.vector_m_s
        norm = max((we * we + wn * wn) ** 0.5, 1e-6)
        up = (-we / norm, -wn / norm)
        across = (-up[1], up[0])
        v = self.speed_m_s
        offset = own.position_enu_m[0] * across[0] + own.position_enu_m[1] * across[1]
        if any([self.detector.hit(value) for _, _, value in values]):  # every sample seen
            self.origin_across_m = offset  # zigzag about the last hit
            return fly(own, (v * up[0], v * up[1]), self.altitude)
        if self.origin_across_m is None:
            self.origin_across_m = offset
        if abs(offset - self.origin_across_m) > self.zigzag_half_width_m:
            self.side = -1.0 if offset > self.origin_across_m else 1.0
        return fly(own, (v * self.side * across[0], v * self.side * across[1]), self.altitude)
