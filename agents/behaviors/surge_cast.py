"""Surge-cast: surge straight upwind while in the plume, cast crosswind only after losing it.

Lochmatter, T. & Martinoli, A. (2008), "Tracking odor plumes in a laminar wind field with
bio-inspired algorithms", *Experimental Robotics* (ISER 2008), Springer STAR 54:473–482; and
Lochmatter's thesis (EPFL 2010). The sensor is read as binary: in the plume when the reading
is at least :data:`~agents.behaviors.search.PLUME_THRESHOLD_G_M3` (with a slow-recovery sensor
such as the metal-oxide preset: when it rose by the equivalent per sample,
:func:`~agents.behaviors.search.detector_for`).

States (``self.state``):

* ``"search"`` — nothing detected yet: cast crosswind legs of growing width around the start;
* ``"surge"`` — in the plume: fly straight upwind at ``surge_speed_m_s``;
* ``"cast"`` — the plume was lost for ``lost_s``: crosswind legs of growing width (first
  ``first_cast_half_width_m``, ×``cast_growth`` per leg) centred where it was lost, drifting
  downwind at
  ``cast_drift_m_s`` so that a searcher that overshot the source comes back into the plume;
* ``"declared"`` — the stopping rule fired (:class:`~agents.behaviors.search.BestReadingDeclarer`):
  the source is declared at the strongest reading and the vehicle holds over it.

Use ``behavior = "agents.behaviors.surge_cast:SurgeCast"``; it holds the altitude it starts at.
"""

from __future__ import annotations

from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behaviors.search import (
    PLUME_THRESHOLD_G_M3,
    BestReadingDeclarer,
    CrosswindSweep,
    SavesState,
    SourceEstimate,
    WindFrame,
    WindReader,
    anemometer_wind,
    detector_for,
    fly,
    hold_at,
    start_or_hold,
)
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState


class SurgeCast(SavesState):
    state_attributes = (
        "detector",
        "state",
        "declarer",
        "declaration",
        "altitude_m",
        "last_hit_s",
        "search",
        "cast",
    )
    surge_speed_m_s = 2.0
    cast_speed_m_s = 2.5
    cast_drift_m_s = 0.5
    first_cast_half_width_m = 3.0
    cast_growth = 1.6
    max_cast_half_width_m = 40.0
    lost_s = 0.5
    threshold_g_m3 = PLUME_THRESHOLD_G_M3

    def __init__(self, ctx: BehaviorContext) -> None:
        self.read_wind: WindReader = anemometer_wind(ctx)
        self.state = "search"
        self.detector = detector_for(ctx, self.threshold_g_m3)
        self.declarer = BestReadingDeclarer(detection_g_m3=self.threshold_g_m3)
        self.declaration: SourceEstimate | None = None
        self.altitude_m: float | None = None
        self.last_hit_s: float | None = None
        side = 1.0 if ctx.vehicle_index % 2 == 0 else -1.0
        self.search = CrosswindSweep(
            self.cast_speed_m_s, 0.0, self.first_cast_half_width_m, self.cast_growth, side=side
        )
        self.cast = CrosswindSweep(
            self.cast_speed_m_s,
            self.cast_drift_m_s,
            self.first_cast_half_width_m,
            self.cast_growth,
            self.max_cast_half_width_m,
        )

    def _observe(self, readings: Sequence[ConcentrationReading]) -> None:
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            self.declarer.observe(r.position_enu_m[0], r.position_enu_m[1], r.reported_g_m3)
            if self.detector.hit(r.reported_g_m3):
                self.last_hit_s = r.sim_time_s

    def _transition(self, now: float) -> None:
        in_plume = self.last_hit_s is not None and now - self.last_hit_s <= self.lost_s
        if in_plume:
            self.state = "surge"
            return
        if self.state == "surge":  # just lost it: cast around here
            self.declaration = self.declarer.lost(now)
            if self.declaration is not None:
                self.state = "declared"
                return
            self.state = "cast"
            self.cast.restart()

    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None:
        x, y, _ = own.position_enu_m
        self.altitude_m, held = start_or_hold(own, self.altitude_m, self.declaration)
        if held is not None:
            return held
        frame = WindFrame.of(self.read_wind(own))
        self._observe(readings)
        self._transition(own.sim_time_s)
        if self.declaration is not None:
            return hold_at(self.declaration.x_m, self.declaration.y_m, self.altitude_m)
        if self.state == "surge":
            return fly(own, frame.velocity(-self.surge_speed_m_s, 0.0), self.altitude_m)
        sweep = self.cast if self.state == "cast" else self.search
        return fly(own, sweep.velocity(frame, x, y), self.altitude_m)
