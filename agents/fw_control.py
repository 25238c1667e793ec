"""Fixed-wing control loops as PX4 flies a plane: TECS (altitude and airspeed → pitch and
throttle), L1 lateral guidance (a line or a loiter circle → lateral acceleration → roll), and
the attitude and rate loops to aileron, elevator and rudder. Parameters by their PX4 names
(``swarmbus.vehicle_types.FixedWingParams``); see docs/agents.md ("Fixed-wing vehicles").

Conventions: positions and velocities world ENU; attitude angles in the aircraft convention
(roll positive right wing down, pitch positive nose up); body rates forward-right-down;
surfaces normalised to −1..1 of their travel with Beard's signs (positive elevator pitches the
nose down, positive aileron rolls right, positive rudder yaws left). Scalar maths.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbus.vehicle_types import FixedWingParams

G = 9.80665


def clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(slots=True)
class Attitude:
    """Roll, pitch (aircraft convention) and ENU course-free heading; FRD body rates."""

    roll: float
    pitch: float
    yaw_enu: float
    p: float
    q: float
    r: float


def attitude_of(
    q_xyzw: tuple[float, float, float, float], rates_flu: tuple[float, float, float]
) -> Attitude:
    """From the body FLU → world ENU quaternion and FLU body rates."""
    x, y, z, w = q_xyzw
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    pitch_flu = math.asin(clip(2.0 * (w * y - z * x), -1.0, 1.0))
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return Attitude(roll, -pitch_flu, yaw, rates_flu[0], -rates_flu[1], -rates_flu[2])


class Tecs:
    """PX4's total energy control: the specific total energy rate error → throttle, the
    energy balance rate error → pitch. Height rate and speed rate demands come from the
    errors over ``FW_T_TIME_CONST``, limited by ``FW_T_CLMB_MAX`` / ``FW_T_SINK_MAX``."""

    def __init__(self, p: FixedWingParams, dt: float) -> None:
        self.p = p
        self.dt = dt
        self.thr_integ = 0.0
        self.pitch_integ = 0.0
        self._speed_rate = 0.0
        self._last_speed: float | None = None

    def reset(self) -> None:
        self.thr_integ = self.pitch_integ = self._speed_rate = 0.0
        self._last_speed = None

    def update(
        self,
        height: float,
        height_sp: float,
        climb_rate: float,
        airspeed: float,
        airspeed_sp: float,
        climb_only: bool = False,
        climb_rate_ff: float = 0.0,
    ) -> tuple[float, float]:
        """(pitch setpoint rad, throttle 0..1). ``climb_only``: pitch controls speed only
        (take-off climb-out: the speed weight at 2, as PX4); ``climb_rate_ff``: a height rate
        feed-forward (m/s; a glide slope's)."""
        p = self.p
        if self._last_speed is not None:  # speed derivative, low-passed over 0.2 s
            raw = (airspeed - self._last_speed) / self.dt
            self._speed_rate += (raw - self._speed_rate) * min(1.0, self.dt / 0.2)
        self._last_speed = airspeed
        k = 1.0 / p.fw_t_time_const
        hdot_sp = clip(k * (height_sp - height) + climb_rate_ff, -p.fw_t_sink_max, p.fw_t_clmb_max)
        vdot_sp = clip(k * (airspeed_sp - airspeed), -2.0, 2.0)
        v = max(airspeed, 1.0)
        ste_rate_sp = G * hdot_sp + v * vdot_sp
        ste_rate = G * climb_rate + v * self._speed_rate
        throttle = self._throttle(ste_rate_sp, ste_rate)
        w = 2.0 if climb_only else p.fw_t_spdweight
        seb_rate_sp = G * hdot_sp * (2.0 - w) - v * vdot_sp * w
        seb_rate = G * climb_rate * (2.0 - w) - v * self._speed_rate * w
        err = seb_rate_sp - seb_rate
        self.pitch_integ = clip(
            self.pitch_integ + err * p.fw_t_integ_gain * self.dt, -G * v * 0.3, G * v * 0.3
        )
        pitch = (seb_rate_sp + p.fw_t_ptch_damp * err + self.pitch_integ) / (G * v)
        pitch += math.radians(p.fw_psp_off)
        pitch = clip(pitch, math.radians(p.fw_p_lim_min), math.radians(p.fw_p_lim_max))
        return pitch, throttle

    def _throttle(self, ste_rate_sp: float, ste_rate: float) -> float:
        p = self.p
        if ste_rate_sp >= 0.0:
            ff = p.fw_thr_trim + ste_rate_sp / (G * p.fw_t_clmb_max) * (
                p.fw_thr_max - p.fw_thr_trim
            )
        else:
            ff = p.fw_thr_trim - ste_rate_sp / (G * p.fw_t_sink_min) * (
                p.fw_thr_min - p.fw_thr_trim
            )
        err = ste_rate_sp - ste_rate
        span = p.fw_thr_max - p.fw_thr_min
        gain = span / (G * (p.fw_t_clmb_max + p.fw_t_sink_min))
        self.thr_integ = clip(
            self.thr_integ + err * gain * p.fw_t_integ_gain * self.dt, -span, span
        )
        thr = ff + err * gain * p.fw_t_thr_damp * 10.0 + self.thr_integ
        return clip(thr, p.fw_thr_min, p.fw_thr_max)


class L1:
    """PX4's L1 guidance: the lateral acceleration (positive: turn left, ENU) to follow a
    line or a loiter circle; ``NAV_L1_PERIOD``, ``NAV_L1_DAMPING``."""

    def __init__(self, p: FixedWingParams) -> None:
        self.period = p.nav_l1_period
        self.damping = p.nav_l1_damping
        self.gain = 4.0 * p.nav_l1_damping**2

    def distance(self, ground_speed: float) -> float:
        return self.damping * self.period / math.pi * ground_speed

    def line(
        self,
        a: tuple[float, float],
        b: tuple[float, float],
        pos: tuple[float, float],
        vel: tuple[float, float],
    ) -> float:
        """Follow the line from ``a`` through ``b``."""
        speed = max(math.hypot(*vel), 1.0)
        l1 = self.distance(speed)
        dx, dy = b[0] - a[0], b[1] - a[1]
        n = math.hypot(dx, dy)
        if n < 1e-6:
            return self.point(b, pos, vel)
        ux, uy = dx / n, dy / n
        apx, apy = pos[0] - a[0], pos[1] - a[1]
        xtrack = ux * apy - uy * apx  # positive: left of the line
        eta1 = math.asin(clip(-xtrack / l1, -0.7071, 0.7071))
        eta2 = math.atan2(-(ux * vel[1] - uy * vel[0]), ux * vel[0] + uy * vel[1])
        eta = clip(eta1 + eta2, -math.pi / 2.0, math.pi / 2.0)
        return self.gain * speed * speed / l1 * math.sin(eta)

    def point(
        self, b: tuple[float, float], pos: tuple[float, float], vel: tuple[float, float]
    ) -> float:
        """Head for the point ``b``."""
        speed = max(math.hypot(*vel), 1.0)
        bearing = math.atan2(b[1] - pos[1], b[0] - pos[0])
        course = math.atan2(vel[1], vel[0])
        eta = clip(wrap_pi(bearing - course), -math.pi / 2.0, math.pi / 2.0)
        return self.gain * speed * speed / self.distance(speed) * math.sin(eta)

    def loiter(
        self,
        centre: tuple[float, float],
        radius: float,
        clockwise: bool,
        pos: tuple[float, float],
        vel: tuple[float, float],
    ) -> float:
        """Circle ``centre`` at ``radius`` (PX4's loiter: PD on the radius error plus the
        centripetal acceleration; L1 toward the centre from far outside)."""
        speed = max(math.hypot(*vel), 1.0)
        rx, ry = pos[0] - centre[0], pos[1] - centre[1]
        dist = max(math.hypot(rx, ry), 1e-3)
        if dist > radius + self.distance(speed):
            return self.point(centre, pos, vel)
        ux, uy = rx / dist, ry / dist  # outward
        sign = -1.0 if clockwise else 1.0  # turn direction: left (ccw) is positive
        omega = 2.0 * math.pi / self.period
        k_x, k_v = omega * omega, 2.0 * self.damping * omega
        err = dist - radius
        radial_vel = ux * vel[0] + uy * vel[1]
        tangential = -uy * vel[0] + ux * vel[1]  # ccw positive
        # inward acceleration wanted: PD on the radius + centripetal of the tangential speed
        inward = k_x * err + k_v * radial_vel + tangential * tangential / max(dist, 0.5 * radius)
        # a turn to the left (ccw flight) accelerates inward: the sign makes it the lateral acc.
        if tangential * sign < 0.0:  # flying the wrong way round: turn toward the direction
            return sign * self.gain * speed * speed / self.distance(speed)
        return sign * inward


@dataclass(slots=True)
class Surfaces:
    aileron: float
    elevator: float
    rudder: float


class AttitudeControl:
    """PX4's fixed-wing attitude and rate controllers: angle errors over ``FW_R_TC`` /
    ``FW_P_TC`` give rate setpoints (with the coordinated-turn yaw rate), rate errors give
    surfaces (P, I, feed-forward, scaled by the trim airspeed over the airspeed; the pitch trim
    by airspeed from ``TRIM_PITCH`` and ``FW_DTRIM_P_VMIN`` / ``_VMAX``)."""

    def __init__(self, p: FixedWingParams, dt: float) -> None:
        self.p = p
        self.dt = dt
        self.roll_integ = 0.0
        self.pitch_integ = 0.0

    def reset(self) -> None:
        self.roll_integ = self.pitch_integ = 0.0

    def pitch_trim(self, airspeed: float) -> float:
        p = self.p
        if airspeed <= p.fw_airspd_trim:
            f = clip((p.fw_airspd_trim - airspeed) / (p.fw_airspd_trim - p.fw_airspd_min), 0.0, 1.0)
            return p.trim_pitch + f * p.fw_dtrim_p_vmin
        f = clip((airspeed - p.fw_airspd_trim) / (p.fw_airspd_max - p.fw_airspd_trim), 0.0, 1.0)
        return p.trim_pitch + f * p.fw_dtrim_p_vmax

    def update(
        self, att: Attitude, roll_sp: float, pitch_sp: float, airspeed: float, integrate: bool
    ) -> Surfaces:
        p = self.p
        v = max(airspeed, p.fw_airspd_min * 0.5)
        scaler = p.fw_airspd_trim / v
        roll_rate_sp = (roll_sp - att.roll) / p.fw_r_tc
        pitch_err = pitch_sp - att.pitch
        # Euler rates → body rates, with the coordinated turn's yaw rate
        yaw_rate = G * math.tan(att.roll) * math.cos(att.pitch) / v
        p_sp = roll_rate_sp - math.sin(att.pitch) * yaw_rate
        q_sp = (
            math.cos(att.roll) * pitch_err / p.fw_p_tc
            + math.sin(att.roll) * math.cos(att.pitch) * yaw_rate
        )
        r_sp = (
            -math.sin(att.roll) * pitch_err / p.fw_p_tc
            + math.cos(att.roll) * math.cos(att.pitch) * yaw_rate
        )
        p_err, q_err = p_sp - att.p, q_sp - att.q
        if integrate:
            self.roll_integ = clip(self.roll_integ + p_err * p.fw_rr_i * self.dt, -0.2, 0.2)
            self.pitch_integ = clip(self.pitch_integ + q_err * p.fw_pr_i * self.dt, -0.4, 0.4)
        s2 = scaler * scaler
        aileron = (p_err * p.fw_rr_p + p_sp * p.fw_rr_ff) * s2 + self.roll_integ
        pull = (q_err * p.fw_pr_p + q_sp * p.fw_pr_ff) * s2 + self.pitch_integ
        elevator = self.pitch_trim(airspeed) - pull  # positive elevator: nose down
        rudder = (att.r - r_sp) * p.fw_yr_p * s2
        return Surfaces(
            clip(aileron, -1.0, 1.0), clip(elevator, -1.0, 1.0), clip(rudder, -1.0, 1.0)
        )
