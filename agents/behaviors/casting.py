"""Cross-wind casting: find the plume, climb its concentration gradient toward the source.

The moth strategy (Kennedy & Marsh 1974, Science 184:999; as a robot algorithm, e.g. Ishida et
al. 1994 and Lochmatter & Martinoli 2008). The wind comes from the wind input
(:mod:`agents.behaviors.search`): while the sensor reads gas (with a slow-recovery sensor such
as the metal-oxide preset: while its reading rises, :func:`~agents.behaviors.search.detector_for`)
the vehicle *surges* upwind, weaving cross-wind and turning back whenever the reading drops
(climbing the cross-wind gradient, which keeps it on the plume's axis). When the gas is lost
for ``lost_s`` it *casts*: cross-wind legs of growing width centred on where it last smelled
gas, drifting slowly downwind so a vehicle that overshot the source finds the plume again.

Stopping rule (:class:`~agents.behaviors.search.BestReadingDeclarer`): when it has lost the
plume twice in a row without finding a stronger reading elsewhere (within 1 m), it declares the
source at its strongest reading (``self.declaration``) and holds over that point.

Use it with ``behavior = "agents.behaviors.casting:Casting"`` on a vehicle and switch that
vehicle to offboard mode once it flies (the behaviour holds the altitude it starts at).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behaviors.search import (
    BestReadingDeclarer,
    SavesState,
    SourceEstimate,
    WindFrame,
    WindReader,
    anemometer_wind,
    detector_for,
    hold_at,
    start_or_hold,
)
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState


class Casting(SavesState):
    state_attributes = (
        "detector",
        "downwind",
        "crosswind",
        "declarer",
        "declaration",
        "was_surging",
        "altitude_m",
        "side",
        "leg_best",
        "last_hit_s",
        "anchor_cross_m",
        "half_width_m",
    )
    surge_speed_m_s = 2.0
    weave_speed_m_s = 1.0
    cast_speed_m_s = 2.5
    cast_drift_m_s = 0.3
    first_cast_half_width_m = 4.0
    cast_growth = 1.5
    max_cast_half_width_m = 40.0
    lost_s = 1.0
    turn_fraction = 0.9
    altitude_gain = 1.0

    def __init__(self, ctx: BehaviorContext) -> None:
        self.read_wind: WindReader = anemometer_wind(ctx)
        toward = math.radians(270.0 - ctx.scenario.wind.from_deg)  # ENU angle the air moves to
        self.downwind = (math.cos(toward), math.sin(toward))
        self.crosswind = (-self.downwind[1], self.downwind[0])
        self.declarer = BestReadingDeclarer()
        self.detector = detector_for(ctx, 0.0)  # a fast sensor: any gas
        self.declaration: SourceEstimate | None = None
        self.was_surging = False
        self.altitude_m: float | None = None
        self.side = 1.0 if ctx.vehicle_index % 2 == 0 else -1.0
        self.leg_best = 0.0  # best reading since the last turn
        self.last_hit_s: float | None = None
        self.anchor_cross_m: float | None = None  # cross-wind coordinate of the last hit
        self.half_width_m = self.first_cast_half_width_m

    def _cross_of(self, x: float, y: float) -> float:
        return x * self.crosswind[0] + y * self.crosswind[1]

    def _update(self, readings: Sequence[ConcentrationReading]) -> None:
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            value = r.reported_g_m3
            self.declarer.observe(r.position_enu_m[0], r.position_enu_m[1], value)
            if self.detector.hit(value):
                if value < self.turn_fraction * self.leg_best:  # going down the gradient: turn
                    self.side = -self.side
                    self.leg_best = value
                self.leg_best = max(self.leg_best, value)
                self.last_hit_s = r.sim_time_s
                self.anchor_cross_m = self._cross_of(r.position_enu_m[0], r.position_enu_m[1])
                self.half_width_m = self.first_cast_half_width_m
            else:
                self.leg_best = 0.0

    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None:
        x, y, z = own.position_enu_m
        self.altitude_m, held = start_or_hold(own, self.altitude_m, self.declaration)
        if held is not None:
            return held
        frame = WindFrame.of(self.read_wind(own))
        self.downwind, self.crosswind = frame.downwind, frame.crosswind
        self._update(readings)
        now = own.sim_time_s
        surging = self.last_hit_s is not None and now - self.last_hit_s <= self.lost_s
        if self.was_surging and not surging:
            self.declaration = self.declarer.lost(now)
            if self.declaration is not None:
                return hold_at(self.declaration.x_m, self.declaration.y_m, self.altitude_m)
        self.was_surging = surging
        dw, cw = self.downwind, self.crosswind
        if surging:
            along, across = -self.surge_speed_m_s, self.weave_speed_m_s * self.side
        else:
            anchor = self.anchor_cross_m
            if anchor is None:
                anchor = self.anchor_cross_m = self._cross_of(x, y)
            offset = self._cross_of(x, y) - anchor
            if offset * self.side > self.half_width_m:  # end of the leg: turn, widen
                self.side = -self.side
                self.half_width_m = min(
                    self.half_width_m * self.cast_growth, self.max_cast_half_width_m
                )
            along, across = self.cast_drift_m_s, self.cast_speed_m_s * self.side
        vx = along * dw[0] + across * cw[0]
        vy = along * dw[1] + across * cw[1]
        vz = self.altitude_gain * (self.altitude_m - z)
        return Setpoint(velocity_enu_m_s=(vx, vy, vz))
