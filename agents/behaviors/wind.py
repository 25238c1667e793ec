"""The wind a source-seeking behaviour reads, and the frame it steers in.

A behaviour reads the wind through a :data:`WindReader`, returning the air velocity (east,
north) in m/s at the vehicle. Built with :func:`anemometer_wind` it is the vehicle's anemometer
(:class:`agents.anemometer.Anemometer`: the scenario's wind at the vehicle's position and the
state's sim time, plus the ``[anemometer]`` noise seeded by (scenario seed, vehicle index,
tick)) — the reading the autopilot process publishes on ``vehicle/<id>/wind``, the same bits in
every runner. :func:`scenario_wind` (the scenario's mean ``[wind]``, noiseless) is kept for
tests. :class:`WindFrame` turns a wind vector into downwind and crosswind unit vectors.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from agents.anemometer import Anemometer
from agents.behavior import BehaviorContext
from plume_atmosphere.plume_formula import downwind_unit
from plume_atmosphere.wind import wind_from_scenario
from swarmbus.messages import VehicleState

#: (east, north) air velocity in m/s at the vehicle, as an anemometer would measure it.
WindReader = Callable[[VehicleState], tuple[float, float]]


def scenario_wind(ctx: BehaviorContext) -> WindReader:
    """The scenario's ``[wind]`` as a :data:`WindReader` (the stand-in for an anemometer)."""
    ux, uy = downwind_unit(ctx.scenario.wind.from_deg)
    speed = ctx.scenario.wind.speed_m_s
    wind = (speed * ux, speed * uy)
    return lambda own: wind


def anemometer_wind(ctx: BehaviorContext) -> WindReader:
    """The vehicle's anemometer as a :data:`WindReader`: read at the state's tick, sim time
    and position (what the autopilot process publishes for that tick)."""
    scenario = ctx.scenario
    wind = wind_from_scenario(scenario)
    anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, ctx.vehicle_index)
    vehicle_id = ctx.vehicle_id

    def read(own: VehicleState) -> tuple[float, float]:
        r = anemometer.read(vehicle_id, own.tick, own.sim_time_s, own.position_enu_m)
        return r.wind_enu_m_s[0], r.wind_enu_m_s[1]

    return read


@dataclass(frozen=True)
class WindFrame:
    """Unit vectors downwind and crosswind (to the left of the wind) from a wind vector."""

    downwind: tuple[float, float]
    crosswind: tuple[float, float]
    speed_m_s: float

    @classmethod
    def of(cls, wind_east_north_m_s: tuple[float, float]) -> WindFrame:
        east, north = wind_east_north_m_s
        speed = math.hypot(east, north)
        if speed <= 1e-9:  # calm: any frame serves; keep the last convention (toward +x)
            return cls((1.0, 0.0), (0.0, 1.0), 0.0)
        dw = (east / speed, north / speed)
        return cls(dw, (-dw[1], dw[0]), speed)

    def velocity(self, along_m_s: float, across_m_s: float) -> tuple[float, float]:
        """ENU (east, north) velocity of ``along`` downwind plus ``across`` crosswind."""
        dw, cw = self.downwind, self.crosswind
        return along_m_s * dw[0] + across_m_s * cw[0], along_m_s * dw[1] + across_m_s * cw[1]

    def coordinates(self, east_m: float, north_m: float) -> tuple[float, float]:
        """(along, across) coordinates of an ENU point in this frame (origin at the ENU origin)."""
        dw, cw = self.downwind, self.crosswind
        return east_m * dw[0] + north_m * dw[1], east_m * cw[0] + north_m * cw[1]
