"""The survey flown by a fixed-wing aircraft: the Aerosonde (``swarmbus/vehicles/aerosonde.toml``)
with its autopilot (:mod:`agents.fixed_wing`: PX4's L1 guidance and TECS) and its physics, in the
fused runner (:class:`plumeswarm.experiments.fused.FusedRunner`: the distributed stack's
World, autopilot, sensor and plume in one process, the same bits).

**The mission** is a racetrack per leg, flown as mission waypoints at the plane's cruise
airspeed (``FW_AIRSPD_TRIM``, 25 m/s for the Aerosonde; ``speed_m_s`` sets another): along the
curtain's line from ``LEAD_M`` crosswind on one side to ``LEAD_M`` on the other, always in the
same direction, then back on a straight ``RETURN_M`` downwind of the curtain. On the curtain's
line the plane descends to the leg's height until ``MARGIN_M`` before the leg, flies the leg
level and climbs again ``MARGIN_M`` after it: its turns and the straight back are never lower
than ``TURN_HEIGHT_M`` (a banked 2.9 m wing near the ground). The long lead lets L1 settle on
the line after the 90° turn onto it (the plane crosses the leg within about 2 m of the curtain's
plane) and TECS on the leg's height (within about 0.2 m). Legs are flown in
:func:`~plumeswarm.survey.flight.leg_order` (up the curtain, then down, …).

**The flight** takes off from a runway ``RETURN_M`` downwind of the curtain, heading along the
curtain's line, ``LEAD_M`` + ``RUNWAY_M`` before it; in a time-dependent environment it is
armed once the release has filled the plume out to the curtain (the benchmark's warm-up,
:func:`plumeswarm.gsl.episode.start_s`), so every reading is of the warmed-up plume.

**The readings** are the vehicle's own sensor readings (``vehicle/<id>/concentration``: the
scenario's sensor model at the position of the sensor tick, every ``period_ticks``, set here
to the nearest of ``sample_hz``) and the wind there through the scenario's anemometer
(:class:`agents.anemometer.Anemometer`), one :class:`~plumeswarm.survey.flux.SurveyReading`
each, from arming to the end of the mission. A reading belongs to a leg within
``HEIGHT_TOLERANCE_M`` of its height (the kinematic runner's 0.5 m is tighter than a plane in
a meandering wind holds).

The geometry (``LEAD_M``, ``RETURN_M``, ``MARGIN_M``, ``TURN_HEIGHT_M``,
``HEIGHT_TOLERANCE_M``) was checked on the tuning environment ``tune_north_c`` (seeds ≥ 1000):
the plane crossed every leg within 1.9 m of the curtain's plane and 0.51 m of the leg's height.
"""

from __future__ import annotations

import itertools
import math
import operator

import msgspec

from agents.anemometer import Anemometer
from plume_atmosphere.wind import wind_from_scenario
from plumeswarm.experiments.fused import FusedRunner
from plumeswarm.gsl.episode import start_s
from plumeswarm.survey.flight import SurveyFlight, leg_order
from plumeswarm.survey.flux import SurveyReading
from plumeswarm.survey.pattern import CurtainPlan, SurveyError
from swarmbus.messages import Arm, FlightMode, MissionItem, MissionStart, MissionUpload
from swarmbus.scenario import Scenario, VehicleSpec

VEHICLE_TYPE = "aerosonde"
VEHICLE_ID = "surveyor"
#: The leg's line starts and ends this far crosswind of the curtain's centre (m).
LEAD_M = 400.0
#: The straight back, this far downwind of the curtain (m).
RETURN_M = 200.0
#: Level at the leg's height from this far before the leg to this far after it (m).
MARGIN_M = 100.0
#: Turns, the straight back and the take-off's climb no lower than this (m above ground).
TURN_HEIGHT_M = 15.0
#: The runway's start, this far before the first leg's line starts (m).
RUNWAY_M = 300.0
#: Mission items per leg: the line's start, level, end of level, the line's end, two corners.
ITEMS_PER_LEG = 6
#: A reading within this of a leg's height belongs to it (at most half the legs' spacing): the
#: plane holds its height on a leg within about 0.5 m in the tuning environments' meander.
HEIGHT_TOLERANCE_M = 1.0
#: Sim seconds allowed per mission item before the flight is refused as lost.
ITEM_TIMEOUT_S = 60.0


def leg_items(plan: CurtainPlan, height_m: float, speed_m_s: float = 0.0) -> list[MissionItem]:
    """One leg's racetrack: the curtain's line from −``LEAD_M`` to +``LEAD_M`` (level at
    ``height_m`` within ``MARGIN_M`` of the leg), then the two corners of the straight back."""
    w, hi = plan.half_width_m, max(height_m, TURN_HEIGHT_M)
    points = (
        (0.0, -LEAD_M, hi),
        (0.0, -w - MARGIN_M, height_m),
        (0.0, w + MARGIN_M, height_m),
        (0.0, LEAD_M, hi),
        (RETURN_M, LEAD_M, hi),
        (RETURN_M, -LEAD_M, hi),
    )
    items = []
    for down, across, up in points:
        x, y, z = plan.enu(down, across, up)
        items.append(MissionItem(x=x, y=y, z=z, speed_m_s=speed_m_s))
    return items


def survey_mission(plan: CurtainPlan, repeats: int, speed_m_s: float = 0.0) -> list[MissionItem]:
    """Every leg's racetrack in flying order, ``repeats`` sweeps."""
    return [
        item
        for leg in leg_order(plan, repeats)
        for item in leg_items(plan, plan.heights_m[leg], speed_m_s)
    ]


def survey_scenario(scenario: Scenario, plan: CurtainPlan, sample_hz: float) -> Scenario:
    """``scenario`` with the surveying plane as its only vehicle on its runway, its sensor read
    every ``control_hz / sample_hz`` ticks (at least 1), its take-off to ``TURN_HEIGHT_M``."""
    ux, uy = plan.downwind
    x, y, _ = plan.enu(RETURN_M, -LEAD_M - RUNWAY_M, 0.0)
    vehicle = VehicleSpec(
        id=VEHICLE_ID,
        type=VEHICLE_TYPE,
        spawn_enu_m=(x, y, 0.0),
        spawn_yaw_deg=math.degrees(math.atan2(ux, -uy)),  # along the curtain, +crosswind
    )
    period = max(1, round(scenario.time.control_hz / sample_hz))
    sensor = msgspec.structs.replace(scenario.sensor, period_ticks=period)
    failsafe = msgspec.structs.replace(scenario.failsafe, takeoff_altitude_m=TURN_HEIGHT_M)
    return msgspec.structs.replace(scenario, vehicles=[vehicle], sensor=sensor, failsafe=failsafe)


def _start_mission(run: FusedRunner, items: list[MissionItem]) -> None:
    for command in (MissionUpload(items=items), Arm(), MissionStart(start_index=0)):
        reply = run.command(VEHICLE_ID, command)
        if not reply.accepted:
            raise SurveyError("mission", f"the plane refused {command!r}: {reply.reason}")


def fly_plane_survey(
    scenario: Scenario,
    plan: CurtainPlan,
    repeats: int = 1,
    sample_hz: float = 20.0,
    speed_m_s: float = 0.0,
) -> SurveyFlight:
    """Fly ``plan`` with the Aerosonde in ``scenario`` (its field, wind, sensor, anemometer and
    seed), ``repeats`` sweeps at ``speed_m_s`` airspeed (0: its cruise); every reading from
    arming to the end of the mission, turns included."""
    if repeats < 1:
        raise SurveyError("repeats", f"{repeats!r} must be 1 or more")
    if not (math.isfinite(sample_hz) and sample_hz > 0.0):
        raise SurveyError("sample_hz", f"{sample_hz!r} must be a positive rate")
    world = survey_scenario(scenario, plan, sample_hz)
    items = survey_mission(plan, repeats, speed_m_s)
    per_sweep = len(plan.heights_m) * ITEMS_PER_LEG
    hz = world.time.control_hz
    arm_tick = round(start_s(scenario, (plan.distance_m, plan.distance_m)) * hz)
    anemometer = Anemometer(world.anemometer, wind_from_scenario(world), world.world.seed, 0)
    readings: list[SurveyReading] = []
    sweep_ends: list[float] = []
    with FusedRunner(world) as run:
        run.step(arm_tick)
        _start_mission(run, items)
        modes = run.flights[VEHICLE_ID].autopilot.modes
        last = -math.inf
        limit = run.tick + round(ITEM_TIMEOUT_S * hz) * (len(items) + 1)
        while modes.mode == FlightMode.MISSION:
            if run.tick >= limit:
                raise SurveyError("mission", f"not flown within {limit / hz:.0f} s of sim time")
            state = run.step(1)[0]
            while len(sweep_ends) < repeats - 1 and modes.mission.index >= per_sweep * (
                len(sweep_ends) + 1
            ):
                sweep_ends.append(state.sim_time_s)
            reading = run.latest_readings.get(VEHICLE_ID)
            if reading is None or reading.sim_time_s <= last:
                continue
            last = reading.sim_time_s
            if reading.reported_g_m3 is None:
                raise SurveyError("sensor", f"no reading at {last:.2f} s: the plume did not answer")
            tick = round(last * hz)
            wind = anemometer.read(VEHICLE_ID, tick, last, reading.position_enu_m).wind_enu_m_s
            readings.append(
                SurveyReading(last, reading.position_enu_m, reading.reported_g_m3, wind[:2])
            )
        if modes.mode != FlightMode.HOLD:
            raise SurveyError("mission", f"ended in mode {modes.mode} at {run.sim_time_s:.1f} s")
    pairs = itertools.pairwise(plan.heights_m[::-1])
    spacing = min(itertools.starmap(operator.sub, pairs), default=math.inf)
    tolerance = min(HEIGHT_TOLERANCE_M, 0.5 * spacing)
    return SurveyFlight(readings, (*sweep_ends, math.inf), tolerance)
