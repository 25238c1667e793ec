"""The fixed-wing pilot: what each flight mode means for a plane, flown with PX4's loops
(:mod:`agents.fw_control`). The mode state machine is the multirotor's
(:class:`agents.modes.FlightModes`: the same commands, refusals and automatic transitions); its
guidance target is read as a plane reads it:

- take-off (mode TAKEOFF, or a mission started on the ground): a runway take-off along the
  heading at arming: full throttle (``FW_THR_MAX``), wings level, rotation at
  ``FW_AIRSPD_MIN``, then climb-out with pitch on airspeed (TECS' speed weight 2) until
  ``FW_CLMBOUT_DIFF`` below the take-off altitude; then loiter over the take-off point;
- hold (also after take-off, after a goto, at a finished mission): loiter at
  ``NAV_LOITER_RAD`` around the target, clockwise as PX4;
- mission waypoints: the L1 line from the previous waypoint; a waypoint is reached within
  ``NAV_ACC_RAD`` (or the item's radius, if larger) horizontally; with ``hold_s > 0`` the
  plane loiters around it and the time counts on the loiter circle;
- landing (a mission's land item, or the LAND mode: straight ahead on the current heading):
  the approach line from the previous waypoint through the landing point, the glide slope
  ``FW_LND_ANG`` at ``FW_LND_AIRSPD_SC`` × ``FW_AIRSPD_MIN``, the flare below
  ``FW_LND_FLALT`` (pitch between ``FW_LND_FL_PMIN`` and ``_PMAX`` on the sink rate), throttle
  off on the ground, disarmed once stopped;
- RTL: loiter over home (or the nearest rally point) at the RTL altitude;
- orbit: loiter around the orbit's centre at its radius, altitude and speed (clockwise for a
  positive speed, as PX4). Offboard, position and follow modes are not flown by a plane (the
  autopilot refuses them).

Airspeed setpoints are never below ``FW_AIRSPD_MIN`` nor above ``FW_AIRSPD_MAX`` (the
autopilot refuses a slower goto or mission item; here it is a clamp). The airspeed is the
vehicle's velocity relative to the scenario's wind at its position (an ideal pitot).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from agents.control import Estimate, Target
from agents.fw_control import L1, AttitudeControl, Tecs, attitude_of, clip
from agents.mission import ResolvedItem
from agents.mode_table import M
from agents.modes import FlightModes
from plume_atmosphere.wind import WindModel
from swarmbus.messages import MissionCommand
from swarmbus.vehicle_types import FixedWing, FixedWingParams

IDLE = [0.0, 0.5, 0.5, 0.5]  # throttle off, surfaces centred
STOPPED_M_S = 1.0  # ground speed under which a landed plane counts as stopped
LAND_FLARE_GAIN = 0.15  # flare pitch, rad per m/s of sink-rate error


def to_channels(throttle: float, aileron: float, elevator: float, rudder: float) -> list[float]:
    """Throttle 0..1 and surfaces −1..1 as the four 0..1 actuator channels."""
    return [throttle, 0.5 + 0.5 * aileron, 0.5 + 0.5 * elevator, 0.5 + 0.5 * rudder]


@dataclass(slots=True)
class Approach:
    """A landing: the approach line from ``start`` through the landing point."""

    start: tuple[float, float]
    point: tuple[float, float, float]


class FixedWingPilot:
    """One fixed wing's guidance and control; ``update`` once per control tick."""

    def __init__(self, fw: FixedWing, dt: float, modes: FlightModes, wind: WindModel) -> None:
        self.p = fw.params
        self.dt = dt
        self.modes = modes
        self.wind = wind
        self.tecs = Tecs(self.p, dt)
        self.l1 = L1(self.p)
        self.att = AttitudeControl(self.p, dt)
        self._launch: tuple[tuple[float, float], float] | None = None  # start xy, heading
        self._runway: tuple[tuple[float, float], float] | None = None  # kept after the launch
        self._leg: tuple[tuple[float, float], tuple[float, float]] | None = None
        self._approach: Approach | None = None
        self._mode = modes.mode
        self.airspeed = 0.0
        modes.waypoint_reached = self.waypoint_reached

    def reset(self) -> None:
        self.tecs.reset()
        self.att.reset()

    def set_params(self, p: FixedWingParams) -> None:
        """New PX4 parameters (a PARAM_SET), in effect from the next tick; the controllers'
        integrators carry on."""
        self.p = self.tecs.p = self.att.p = p
        self.l1 = L1(p)

    # ------------------------------------------------------------------ mission acceptance
    def waypoint_reached(self, item: ResolvedItem, est: Estimate) -> bool:
        """Within the radius horizontally, or past the waypoint along its leg (a plane that
        missed the radius does not turn back for it, as PX4's); a loiter item on its circle."""
        x, y, _ = est.position
        dist = math.hypot(x - item.x, y - item.y)
        radius = max(item.acceptance_radius_m, self.p.nav_acc_rad)
        if item.hold_s > 0.0:  # a loiter: the time counts on the circle
            return abs(dist - self.p.nav_loiter_rad) < radius or dist < radius
        if self._leg is not None and self._leg[1] == (item.x, item.y):
            (ax, ay), (bx, by) = self._leg
            if (bx - ax) * (x - bx) + (by - ay) * (y - by) > 0.0:
                return True
        return dist < radius

    # ------------------------------------------------------------------ tick
    def update(self, est: Estimate, target: Target | None, now: float) -> list[float]:
        modes = self.modes
        if modes.mode != self._mode:
            self._mode_changed(est)
        if target is None:
            self.reset()
            self._launch = None
            return list(IDLE)
        self.airspeed = self._airspeed(est, now)
        if self._launching(est):
            return self._take_off(est)
        landing = self._landing_point(est)
        if landing is not None:
            return self._land(est, landing, now)
        return self._fly(est, target)

    def _mode_changed(self, est: Estimate) -> None:
        self._mode = self.modes.mode
        self._approach = None
        if est.on_ground and self._mode in (M.TAKEOFF, M.MISSION):
            x, y, _ = est.position
            self._launch = ((x, y), attitude_of(est.attitude_xyzw, est.body_rates).yaw_enu)
            self._runway = self._launch

    def _airspeed(self, est: Estimate, now: float) -> float:
        wx, wy, wz = self._wind(est, now)
        vx, vy, vz = est.velocity
        return math.sqrt((vx - wx) ** 2 + (vy - wy) ** 2 + (vz - wz) ** 2)

    def _wind(self, est: Estimate, now: float) -> tuple[float, float, float]:
        uniform = self.wind.uniform_at(now)
        if uniform is not None:
            return (float(uniform[0]), float(uniform[1]), float(uniform[2]))
        w = self.wind.velocity([est.position], now)[0]
        return (float(w[0]), float(w[1]), float(w[2]))

    def _speed_sp(self, requested: float) -> float:
        p = self.p
        if requested <= 0.0:
            return p.fw_airspd_trim
        return clip(requested, p.fw_airspd_min, p.fw_airspd_max)

    def _control(
        self,
        est: Estimate,
        lateral_acc: float,
        pitch_sp: float,
        throttle: float,
        roll_limit: float | None = None,
    ) -> list[float]:
        att = attitude_of(est.attitude_xyzw, est.body_rates)
        limit = math.radians(self.p.fw_r_lim) if roll_limit is None else roll_limit
        roll_sp = clip(-math.atan(lateral_acc / 9.80665), -limit, limit)
        s = self.att.update(att, roll_sp, pitch_sp, self.airspeed, integrate=not est.on_ground)
        return to_channels(throttle, s.aileron, s.elevator, s.rudder)

    # ------------------------------------------------------------------ take-off
    def _launching(self, est: Estimate) -> bool:
        if self._launch is None:
            return False
        target_z = self._climb_altitude()
        if est.position[2] > target_z - self.p.fw_clmbout_diff:
            self._launch = None
            return False
        return True

    def _climb_altitude(self) -> float:
        m = self.modes
        item = m.mission.current
        if m.mode == M.TAKEOFF or item is None:
            return m.home[2] + m.failsafe.takeoff_altitude_m
        return max(item.z, m.home[2] + m.failsafe.takeoff_altitude_m)

    def _take_off(self, est: Estimate) -> list[float]:
        assert self._launch is not None
        p = self.p
        (sx, sy), heading = self._launch
        ahead = (sx + 1000.0 * math.cos(heading), sy + 1000.0 * math.sin(heading))
        x, y, z = est.position
        lateral = self.l1.line((sx, sy), ahead, (x, y), (est.velocity[0], est.velocity[1]))
        if est.on_ground and self.airspeed < p.fw_airspd_min:
            # ground roll: wings level, nose on the runway
            return self._control(est, lateral, 0.0, p.fw_thr_max, roll_limit=0.0)
        pitch, _ = self.tecs.update(
            z,
            self._climb_altitude(),
            est.velocity[2],
            self.airspeed,
            p.fw_airspd_trim,
            climb_only=True,
        )
        pitch = max(pitch, math.radians(p.fw_tko_pitch_min))
        limit = math.radians(p.fw_r_lim) if z - self.modes.home[2] > 5.0 else math.radians(5.0)
        return self._control(est, lateral, pitch, p.fw_thr_max, roll_limit=limit)

    # ------------------------------------------------------------------ cruise
    def _fly(self, est: Estimate, target: Target) -> list[float]:
        x, y, z = est.position
        pos, vel = (x, y), (est.velocity[0], est.velocity[1])
        centre, height, speed = self._cruise_target(est, target)
        runway = self._runway_line(centre)
        if runway is not None:
            lateral = self.l1.line(runway[0], runway[1], pos, vel)
        elif self._loitering():
            radius, clockwise = self.p.nav_loiter_rad, True
            orbit = self.modes.orbit_command
            if self.modes.mode == M.ORBIT and orbit is not None:
                radius, clockwise = orbit.radius_m, orbit.speed_m_s >= 0.0
            lateral = self.l1.loiter(centre, radius, clockwise, pos, vel)
        else:
            lateral = self.l1.line(self._leg_start(centre, pos), centre, pos, vel)
        pitch, throttle = self.tecs.update(
            z, height, est.velocity[2], self.airspeed, self._speed_sp(speed)
        )
        return self._control(est, lateral, pitch, throttle)

    def _cruise_target(
        self, est: Estimate, target: Target
    ) -> tuple[tuple[float, float], float, float]:
        m = self.modes
        if m.mode == M.RTL:
            (hx, hy, _), alt = m.rtl_target
            return (hx, hy), alt, 0.0
        orbit = m.orbit_command
        if m.mode == M.ORBIT and orbit is not None:
            cx, cy, cz = orbit.center_enu_m
            return (cx, cy), cz, abs(orbit.speed_m_s)
        xy = target.position_xy if target.position_xy is not None else est.position[:2]
        z = target.position_z if target.position_z is not None else est.position[2]
        return (xy[0], xy[1]), z, target.max_speed_xy_m_s

    def _runway_line(
        self, centre: tuple[float, float]
    ) -> tuple[tuple[float, float], tuple[float, float]] | None:
        """A mission started on the ground climbs to its first altitude over the launch point
        (its target): the plane climbs on along the runway's line instead of turning back."""
        if self._runway is None or self.modes.mode != M.MISSION:
            self._runway = None
            return None
        (sx, sy), heading = self._runway
        if math.hypot(centre[0] - sx, centre[1] - sy) > 1.0:  # the mission's own items now
            self._runway = None
            return None
        return (sx, sy), (sx + 1000.0 * math.cos(heading), sy + 1000.0 * math.sin(heading))

    def _loitering(self) -> bool:
        """Loiter (rather than follow a leg) around the target: from far away the loiter
        heads for the centre first."""
        m = self.modes
        if m.mode in (M.HOLD, M.TAKEOFF, M.RTL, M.ORBIT):
            return True
        item = m.mission.current
        return m.mode == M.MISSION and item is not None and item.hold_s > 0.0

    def _leg_start(
        self, centre: tuple[float, float], pos: tuple[float, float]
    ) -> tuple[float, float]:
        """The previous target (the start of the leg to ``centre``), or where the plane was
        when ``centre`` became the target."""
        if self._leg is None or self._leg[1] != centre:
            start = self._leg[1] if self._leg is not None else pos
            self._leg = (start, centre)
        return self._leg[0]

    # ------------------------------------------------------------------ landing
    def _landing_point(self, est: Estimate) -> Approach | None:
        m = self.modes
        if self._approach is not None:
            return self._approach
        x, y, z = est.position
        item = m.mission.current
        if m.mode == M.MISSION and item is not None and item.command == MissionCommand.LAND:
            start = self._leg[1] if self._leg is not None else (x, y)
            self._approach = Approach(start, (item.x, item.y, item.z))
        elif m.mode == M.LAND:  # straight ahead, on the glide slope from here
            heading = math.atan2(est.velocity[1], est.velocity[0])
            run = max(z - m.home[2], 0.0) / math.tan(math.radians(self.p.fw_lnd_ang))
            point = (x + run * math.cos(heading), y + run * math.sin(heading), m.home[2])
            self._approach = Approach((x, y), point)
        return self._approach

    def _land(self, est: Estimate, a: Approach, now: float) -> list[float]:
        p = self.p
        x, y, z = est.position
        lx, ly, lz = a.point
        pos, vel = (x, y), (est.velocity[0], est.velocity[1])
        if est.on_ground:
            if math.hypot(*vel) < STOPPED_M_S:
                self.modes.landed(est, now)
            return self._control(est, 0.0, 0.0, 0.0, roll_limit=0.0)
        dx, dy = lx - a.start[0], ly - a.start[1]
        n = max(math.hypot(dx, dy), 1e-6)
        beyond = (lx + dx / n * 1000.0, ly + dy / n * 1000.0)
        lateral = self.l1.line(a.start, beyond, pos, vel)
        to_go = ((lx - x) * dx + (ly - y) * dy) / n  # along the approach, to the point
        height = z - lz
        if height < p.fw_lnd_flalt:  # flare: pitch on the sink rate, throttle at minimum
            pitch = math.radians(p.fw_lnd_fl_pmin) + LAND_FLARE_GAIN * (
                -p.fw_lnd_fl_sink - est.velocity[2]
            )
            pitch = clip(pitch, math.radians(p.fw_lnd_fl_pmin), math.radians(p.fw_lnd_fl_pmax))
            return self._control(est, lateral, pitch, p.fw_thr_min, roll_limit=math.radians(5.0))
        slope = math.tan(math.radians(p.fw_lnd_ang))
        glide = lz + max(to_go, 0.0) * slope
        along = (vel[0] * dx + vel[1] * dy) / n  # ground speed toward the landing point
        on_slope = glide < z + 1.0  # not below it: descend along it (its sink feed-forward)
        pitch, throttle = self.tecs.update(
            z,
            min(glide, z + 1.0),
            est.velocity[2],
            self.airspeed,
            p.fw_lnd_airspd_sc * p.fw_airspd_min,
            climb_rate_ff=-max(along, 0.0) * slope if on_slope and to_go > 0.0 else 0.0,
        )
        return self._control(est, lateral, pitch, throttle)
