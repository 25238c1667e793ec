"""Cascaded multirotor control: position → velocity → attitude → body rate → (thrust, torques),
gains from ``VehicleType.gains``. Scalar maths on tuples, not numpy: on 3-vectors numpy's
per-call cost would dominate. World ENU, body FLU, SI units; yaw is the ENU heading of the body
x axis (0 along +x, counter-clockwise positive). See docs/agents.md ("Control and tuning").
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from swarmbus.vehicle_types import VehicleType

GRAVITY_M_S2 = 9.80665
MAX_TILT_RATE_RAD_S = math.radians(220.0)
# Integrator authority: the velocity integrator may hold off up to this much acceleration
# (wind drag, mass error); the rate integrator this much torque.
_VEL_I_LIMIT_XY_M_S2 = 4.0
_VEL_I_LIMIT_Z_M_S2 = 4.0
_RATE_I_LIMIT_NM = 0.3
_VEL_I_BAND_M_S = 1.0
_MIN_THRUST_FRACTION = 0.05  # of weight: keeps the desired body z defined when falling
_MAX_THRUST_FRACTION = 0.95  # of max total thrust: leaves room for attitude control

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]  # x, y, z, w (body → world)


@dataclass(slots=True)
class Estimate:
    """The autopilot's view of its vehicle (ENU / FLU)."""

    position: Vec3
    velocity: Vec3
    attitude_xyzw: Quat
    body_rates: Vec3
    on_ground: bool = False


@dataclass(slots=True)
class Target:
    """What the guidance asks of the controller this tick.

    ``position_xy`` / ``position_z`` ``None`` means that axis follows ``velocity`` alone;
    otherwise ``velocity`` is a feed-forward added to the position loop's output.
    ``max_speed_xy_m_s`` 0 means the vehicle's limit.
    """

    position_xy: tuple[float, float] | None
    position_z: float | None
    yaw_rad: float
    velocity: Vec3 = (0.0, 0.0, 0.0)
    max_speed_xy_m_s: float = 0.0
    # offboard extras: acceleration feed-forward (alone when ``velocity_loop`` is off), or an
    # attitude / body rates with a collective thrust (fraction of the maximum), loops bypassed
    acceleration: Vec3 = (0.0, 0.0, 0.0)
    velocity_loop: bool = True
    attitude: Quat | None = None
    body_rates: Vec3 | None = None
    thrust_fraction: float = 0.0


def yaw_of(q: Quat) -> float:
    """ENU heading of the body x axis."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _clip(v: float, lo: float, hi: float) -> float:
    return lo if v < lo else hi if v > hi else v


def _quat_from_matrix(
    r00: float,
    r01: float,
    r02: float,
    r10: float,
    r11: float,
    r12: float,
    r20: float,
    r21: float,
    r22: float,
) -> Quat:
    trace = r00 + r11 + r22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s, 0.25 * s)
    if r00 > r11 and r00 > r22:
        s = 2.0 * math.sqrt(1.0 + r00 - r11 - r22)
        return (0.25 * s, (r01 + r10) / s, (r02 + r20) / s, (r21 - r12) / s)
    if r11 > r22:
        s = 2.0 * math.sqrt(1.0 + r11 - r00 - r22)
        return ((r01 + r10) / s, 0.25 * s, (r12 + r21) / s, (r02 - r20) / s)
    s = 2.0 * math.sqrt(1.0 + r22 - r00 - r11)
    return ((r02 + r20) / s, (r12 + r21) / s, 0.25 * s, (r10 - r01) / s)


def desired_attitude(fx: float, fy: float, fz: float, yaw_rad: float) -> Quat:
    """Attitude whose body z is along the thrust vector and whose heading is ``yaw_rad``."""
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    b3x, b3y, b3z = fx / norm, fy / norm, fz / norm
    c1x, c1y = math.cos(yaw_rad), math.sin(yaw_rad)
    # b2 = b3 × c1 (c1 has no z component)
    b2x, b2y, b2z = -b3z * c1y, b3z * c1x, b3x * c1y - b3y * c1x
    n2 = math.sqrt(b2x * b2x + b2y * b2y + b2z * b2z)
    b2x, b2y, b2z = b2x / n2, b2y / n2, b2z / n2
    # b1 = b2 × b3
    b1x = b2y * b3z - b2z * b3y
    b1y = b2z * b3x - b2x * b3z
    b1z = b2x * b3y - b2y * b3x
    return _quat_from_matrix(b1x, b2x, b3x, b1y, b2y, b3y, b1z, b2z, b3z)


class Controller:
    """One vehicle's cascaded controller; ``update`` once per control tick."""

    def __init__(self, vehicle: VehicleType, dt_s: float) -> None:
        g = vehicle.gains
        self.dt = dt_s
        self.mass = vehicle.mass_kg
        self.inertia = vehicle.inertia_kg_m2
        self.max_thrust_n = vehicle.max_total_thrust_n
        self.pos_p = g.pos_p
        self.vel_p = g.vel_p
        self.vel_i = g.vel_i
        self.vel_d = g.vel_d
        self.att_p = g.att_p
        self.rate_p = g.rate_p
        self.rate_i = g.rate_i
        self.rate_d = g.rate_d
        self.tan_tilt = math.tan(math.radians(g.max_tilt_deg))
        self.max_xy = g.max_speed_xy_m_s
        self.max_up = g.max_speed_up_m_s
        self.max_down = g.max_speed_down_m_s
        self.max_yaw_rate = math.radians(g.max_yaw_rate_deg_s)
        self.reset()

    def reset(self) -> None:
        """Forget integrators and derivative memory (on arming, on touchdown)."""
        self._vi = [0.0, 0.0, 0.0]
        self._ri = [0.0, 0.0, 0.0]
        self._v_prev: Vec3 | None = None
        self._w_prev: Vec3 | None = None

    # ------------------------------------------------------------------ loops
    def velocity_setpoint(self, est: Estimate, target: Target) -> Vec3:
        px, py, pz = est.position
        fx, fy, fz = target.velocity
        if target.position_xy is not None:
            fx += self.pos_p[0] * (target.position_xy[0] - px)
            fy += self.pos_p[1] * (target.position_xy[1] - py)
        if target.position_z is not None:
            fz += self.pos_p[2] * (target.position_z - pz)
        limit = target.max_speed_xy_m_s or self.max_xy
        limit = min(limit, self.max_xy)
        speed = math.hypot(fx, fy)
        if speed > limit:
            fx, fy = fx * limit / speed, fy * limit / speed
        return fx, fy, _clip(fz, -self.max_down, self.max_up)

    def thrust_vector(
        self,
        est: Estimate,
        vsp: Vec3 | None,
        integrate: bool,
        accel_ff: Vec3 = (0.0, 0.0, 0.0),
    ) -> Vec3:
        """World-frame thrust (N) for the velocity setpoint plus an acceleration feed-forward
        (``vsp`` None: the acceleration alone), tilt- and thrust-limited."""
        if vsp is None:
            return self._limited_thrust(*accel_ff)
        dt = self.dt
        vx, vy, vz = est.velocity
        ex, ey, ez = vsp[0] - vx, vsp[1] - vy, vsp[2] - vz
        vi = self._vi
        if integrate:
            lim = (_VEL_I_LIMIT_XY_M_S2, _VEL_I_LIMIT_XY_M_S2, _VEL_I_LIMIT_Z_M_S2)
            for k, e in enumerate((ex, ey, ez)):
                # conditional integration: large errors (accelerating) would wind it up
                if self.vel_i[k] > 0.0 and -_VEL_I_BAND_M_S < e < _VEL_I_BAND_M_S:
                    vi[k] = _clip(vi[k] + e * dt, -lim[k] / self.vel_i[k], lim[k] / self.vel_i[k])
        prev = self._v_prev or est.velocity
        self._v_prev = est.velocity
        p, i, d = self.vel_p, self.vel_i, self.vel_d
        ax = p[0] * ex + i[0] * vi[0] - d[0] * (vx - prev[0]) / dt
        ay = p[1] * ey + i[1] * vi[1] - d[1] * (vy - prev[1]) / dt
        az = p[2] * ez + i[2] * vi[2] - d[2] * (vz - prev[2]) / dt
        return self._limited_thrust(ax + accel_ff[0], ay + accel_ff[1], az + accel_ff[2])

    def _limited_thrust(self, ax: float, ay: float, az: float) -> Vec3:
        m = self.mass
        weight = m * GRAVITY_M_S2
        t_max = _MAX_THRUST_FRACTION * self.max_thrust_n
        fz = _clip(m * (az + GRAVITY_M_S2), _MIN_THRUST_FRACTION * weight, t_max)
        fx, fy = m * ax, m * ay
        f_xy = math.hypot(fx, fy)
        xy_max = min(fz * self.tan_tilt, math.sqrt(max(t_max * t_max - fz * fz, 0.0)))
        if f_xy > xy_max:
            fx, fy = fx * xy_max / f_xy, fy * xy_max / f_xy
        return fx, fy, fz

    def rate_setpoint(self, q: Quat, qd: Quat) -> Vec3:
        """Body-rate setpoint from the attitude error q⁻¹ ⊗ q_d (shortest way round)."""
        x1, y1, z1, w1 = -q[0], -q[1], -q[2], q[3]
        x2, y2, z2, w2 = qd
        ew = w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2
        ex = w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2
        ey = w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2
        ez = w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2
        k = 2.0 if ew >= 0.0 else -2.0
        a = self.att_p
        return (
            _clip(k * a[0] * ex, -MAX_TILT_RATE_RAD_S, MAX_TILT_RATE_RAD_S),
            _clip(k * a[1] * ey, -MAX_TILT_RATE_RAD_S, MAX_TILT_RATE_RAD_S),
            _clip(k * a[2] * ez, -self.max_yaw_rate, self.max_yaw_rate),
        )

    def torques(self, w: Vec3, wsp: Vec3, integrate: bool) -> Vec3:
        dt = self.dt
        prev = self._w_prev or w
        self._w_prev = w
        ri = self._ri
        out = [0.0, 0.0, 0.0]
        for k in range(3):
            e = wsp[k] - w[k]
            if integrate and self.rate_i[k] > 0.0:
                lim = _RATE_I_LIMIT_NM / self.rate_i[k]
                ri[k] = _clip(ri[k] + e * dt, -lim, lim)
            out[k] = (
                self.rate_p[k] * e + self.rate_i[k] * ri[k] - self.rate_d[k] * (w[k] - prev[k]) / dt
            )
        ix, iy, iz = self.inertia
        # ω × Jω: the gyroscopic torque the body needs to keep rotating as asked
        out[0] += (iz - iy) * w[1] * w[2]
        out[1] += (ix - iz) * w[2] * w[0]
        out[2] += (iy - ix) * w[0] * w[1]
        return out[0], out[1], out[2]

    def update(
        self, est: Estimate, target: Target, integrate: bool = True
    ) -> tuple[float, float, float, float]:
        """Collective thrust (N) and body torques (N·m) for this tick.

        ``integrate`` false freezes the integrators (on the ground, where the vehicle cannot
        follow the setpoint and integrators would wind up).
        """
        q = est.attitude_xyzw
        direct = target.body_rates
        if direct is None and target.attitude is not None:
            direct = self.rate_setpoint(q, target.attitude)
        if direct is not None:  # attitude / rate offboard: the outer loops are bypassed
            tx, ty, tz = self.torques(est.body_rates, direct, integrate)
            return target.thrust_fraction * self.max_thrust_n, tx, ty, tz
        vsp = self.velocity_setpoint(est, target) if target.velocity_loop else None
        fx, fy, fz = self.thrust_vector(est, vsp, integrate, target.acceleration)
        qd = desired_attitude(fx, fy, fz, target.yaw_rad)
        wsp = self.rate_setpoint(q, qd)
        tx, ty, tz = self.torques(est.body_rates, wsp, integrate)
        x, y, z, w = q
        # collective thrust = thrust vector projected on the current body z axis
        b3x, b3y, b3z = 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)
        thrust = max(fx * b3x + fy * b3y + fz * b3z, 0.0)
        return thrust, tx, ty, tz
