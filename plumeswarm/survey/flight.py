"""A survey flown by the kinematic runner: a point moving at a constant ground speed along the
curtain's legs and the turns between them, reading the environment's field and wind as a
vehicle of the benchmark does.

**The path** is a racetrack per leg, the shape a fixed-wing aircraft flies: the leg across the
curtain (always in the same direction, from −W to +W crosswind), a turn of radius r onto the
downwind side, a straight back 2r downwind of the curtain, and a turn back onto the curtain's
next leg; the height changes from one leg's to the next's, linearly along the turns and the
straight back. The default radius is the level turn of a plane at the survey speed and a 30°
bank, r = v²/(g·tan 30°): 57 m at 18 m/s. A multirotor can fly the same path (or any radius);
only the readings on the curtain's legs enter the estimate, so any vehicle that crosses the
curtain at the planned heights gives one.

**The readings**, every ``1/sample_hz`` s of sim time: the field's value at the point through
the scenario's sensor model (:class:`agents.sensor.ConcentrationSensor`) and the wind through
the scenario's anemometer (:class:`agents.anemometer.Anemometer`: the wind at the point plus
its noise, seeded by the scenario's seed and the tick) — the same models the autopilots use.
In a time-dependent environment the flight starts once the release has reached the curtain's
distance in its statistically steady state (the benchmark's warm-up,
:func:`plumeswarm.gsl.episode.start_s`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agents.anemometer import Anemometer
from agents.sensor import ConcentrationSensor
from plumeswarm.gsl.episode import environment_field, start_s
from plumeswarm.survey.flux import SurveyReading
from plumeswarm.survey.pattern import CurtainPlan, SurveyError
from swarmbus.scenario import Scenario

#: The survey's ground speed (m/s): a small fixed-wing UAV's cruise.
SURVEY_SPEED_M_S = 18.0
#: The bank angle of the default turn.
BANK_DEG = 30.0
GRAVITY_M_S2 = 9.81
#: Readings per second of sim time.
SAMPLE_HZ = 20.0


def turn_radius_m(speed_m_s: float, bank_deg: float = BANK_DEG) -> float:
    """The radius of a level, coordinated turn at ``speed_m_s`` and ``bank_deg``."""
    return speed_m_s**2 / (GRAVITY_M_S2 * math.tan(math.radians(bank_deg)))


def leg_order(plan: CurtainPlan, repeats: int) -> list[int]:
    """The legs in flying order: up the curtain, then down, ``repeats`` sweeps."""
    up = list(range(len(plan.heights_m)))
    return [k for sweep in range(repeats) for k in (up if sweep % 2 == 0 else up[::-1])]


@dataclass(frozen=True)
class Racetrack:
    """The path of a survey in the curtain's frame (downwind of the curtain, crosswind, up)."""

    plan: CurtainPlan
    legs: tuple[int, ...]
    radius_m: float

    @property
    def lap_m(self) -> float:
        return 4.0 * self.plan.half_width_m + 2.0 * math.pi * self.radius_m

    @property
    def length_m(self) -> float:
        """From the first leg's start to the last leg's end."""
        return (len(self.legs) - 1) * self.lap_m + 2.0 * self.plan.half_width_m

    def at(self, s: float) -> tuple[float, float, float]:
        """The point ``s`` metres along the path: (downwind, crosswind, up)."""
        w, r = self.plan.half_width_m, self.radius_m
        lap = min(int(s // self.lap_m), len(self.legs) - 1)
        u = s - lap * self.lap_m
        z0 = self.plan.heights_m[self.legs[lap]]
        if u <= 2.0 * w:
            return 0.0, -w + u, z0
        z1 = self.plan.heights_m[self.legs[min(lap + 1, len(self.legs) - 1)]]
        climb = u - 2.0 * w
        z = z0 + (z1 - z0) * climb / (self.lap_m - 2.0 * w)
        half_turn = math.pi * r
        if climb <= half_turn:  # at +W: from heading +y round to −y, on the downwind side
            a = climb / r
            return r - r * math.cos(a), w + r * math.sin(a), z
        if climb <= half_turn + 2.0 * w:
            return 2.0 * r, w - (climb - half_turn), z
        a = (climb - half_turn - 2.0 * w) / r  # at −W: from heading −y round to +y
        return r + r * math.cos(a), -w - r * math.sin(a), z


@dataclass(frozen=True)
class SurveyFlight:
    """A flown survey: its readings, and when each sweep of the curtain ended (the readings of
    sweeps 1…j are those before ``sweep_ends_s[j - 1]``; the last end is infinite)."""

    readings: list[SurveyReading]
    sweep_ends_s: tuple[float, ...]
    #: How far from a leg's height a reading still belongs to the leg (the estimate's
    #: ``height_tolerance_m``): as tightly as the vehicle holds its altitude.
    height_tolerance_m: float = 0.5

    def through_sweep(self, sweeps: int) -> list[SurveyReading]:
        """The readings of the first ``sweeps`` sweeps."""
        end = self.sweep_ends_s[sweeps - 1]
        return [r for r in self.readings if r.sim_time_s < end]


def fly_survey(
    scenario: Scenario,
    plan: CurtainPlan,
    speed_m_s: float = SURVEY_SPEED_M_S,
    radius_m: float | None = None,
    repeats: int = 1,
    sample_hz: float = SAMPLE_HZ,
) -> list[SurveyReading]:
    """Fly ``plan`` in ``scenario`` (its field, wind, sensor, anemometer and seed) at
    ``speed_m_s`` around turns of ``radius_m`` (default :func:`turn_radius_m`), ``repeats``
    sweeps of the curtain; every reading, turns included."""
    if not (math.isfinite(speed_m_s) and speed_m_s > 0.0):
        raise SurveyError("speed_m_s", f"{speed_m_s!r} must be a positive speed")
    if repeats < 1:
        raise SurveyError("repeats", f"{repeats!r} must be 1 or more")
    if not (math.isfinite(sample_hz) and sample_hz > 0.0):
        raise SurveyError("sample_hz", f"{sample_hz!r} must be a positive rate")
    radius = turn_radius_m(speed_m_s) if radius_m is None else radius_m
    if not (math.isfinite(radius) and radius > 0.0):
        raise SurveyError("radius_m", f"{radius!r} must be a positive radius")
    path = Racetrack(plan, tuple(leg_order(plan, repeats)), radius)
    concentration, wind = environment_field(scenario)
    sensor = ConcentrationSensor.for_vehicle(scenario, 0)
    anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, 0)
    dt = 1.0 / sample_hz
    first = round(start_s(scenario, (plan.distance_m, plan.distance_m)) / dt)
    readings = []
    for k in range(math.floor(path.length_m / (speed_m_s * dt)) + 1):
        tick = first + k
        t = tick * dt
        point = plan.enu(*path.at(k * dt * speed_m_s))
        true = float(concentration(np.array([point], dtype=np.float64), t)[0])
        measured = anemometer.read("survey", tick, t, point).wind_enu_m_s
        readings.append(SurveyReading(t, point, sensor.sample(true, t), (measured[0], measured[1])))
    return readings


def kinematic_flight(
    scenario: Scenario,
    plan: CurtainPlan,
    speed_m_s: float = SURVEY_SPEED_M_S,
    repeats: int = 1,
    sample_hz: float = SAMPLE_HZ,
) -> SurveyFlight:
    """:func:`fly_survey` (default radius) with the end of each sweep: the start of the next
    sweep's first leg."""
    readings = fly_survey(scenario, plan, speed_m_s, repeats=repeats, sample_hz=sample_hz)
    lap_s = Racetrack(plan, (0,), turn_radius_m(speed_m_s)).lap_m / speed_m_s
    t0, legs = readings[0].sim_time_s, len(plan.heights_m)
    ends = tuple(t0 + (j + 1) * legs * lap_s for j in range(repeats - 1))
    return SurveyFlight(readings, (*ends, math.inf))


def flight_time_s(readings: Sequence[SurveyReading]) -> float:
    """From the first reading to the last."""
    return readings[-1].sim_time_s - readings[0].sim_time_s if readings else 0.0
