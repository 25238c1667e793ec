"""Control allocation: collective thrust + body torques → normalised rotor commands.

The allocation matrix comes from the vehicle type's rotor layout, so every multirotor (quad,
hexa, …) shares one code path: row 0 is the collective thrust, rows 1-3 the body torques (FLU)
produced by one newton of thrust on each rotor. A rotor at (x, y) pushing along body +z makes
the torque r × F = (y·T, −x·T, 0); its reaction torque about z is −spin·(k_m/k_f)·T
(docs/physics.md, the rotor command). The pseudo-inverse (exact for a quad) is computed once; the
per-tick work is a handful of scalar multiply-adds.

When the request does not fit the rotors' range, yaw gives way first, then roll/pitch are
scaled down, so that attitude (and the vehicle) is kept before heading.
"""

from __future__ import annotations

import math

import numpy as np

from swarmbus.vehicle_types import VehicleType


def allocation_matrix(vehicle: VehicleType) -> np.ndarray:
    """The 4×n matrix mapping per-rotor thrust (N) to (thrust N, τx, τy, τz N·m)."""
    ratio = vehicle.torque_coeff_nm_per_rad2_s2 / vehicle.thrust_coeff_n_per_rad2_s2
    cols = [(1.0, r.position_m[1], -r.position_m[0], -r.spin * ratio) for r in vehicle.rotors]
    return np.array(cols, dtype=float).T


class Mixer:
    """Per-vehicle-type allocator (build once, call every control tick)."""

    def __init__(self, vehicle: VehicleType) -> None:
        self.rotor_count = len(vehicle.rotors)
        self.k_f = vehicle.thrust_coeff_n_per_rad2_s2
        self.omega_max = vehicle.max_rotor_speed_rad_s
        self.max_rotor_thrust_n = self.k_f * self.omega_max**2
        pinv = np.linalg.pinv(allocation_matrix(vehicle))  # n×4
        rows: list[tuple[float, float, float, float]] = [
            (float(a), float(b), float(c), float(d)) for a, b, c, d in pinv.tolist()
        ]
        self._rows = rows

    def rotor_thrusts(
        self, thrust_n: float, torque_x: float, torque_y: float, torque_z: float
    ) -> list[float]:
        """Per-rotor thrust (N) within [0, max], yaw then roll/pitch reduced to fit."""
        t_max = self.max_rotor_thrust_n
        mid, yaw, s_yaw = self._fit(thrust_n, torque_x, torque_y, torque_z)
        return [min(max(m + s_yaw * d, 0.0), t_max) for m, d in zip(mid, yaw, strict=True)]

    def commands(
        self, thrust_n: float, torque_x: float, torque_y: float, torque_z: float
    ) -> list[float]:
        """Rotor commands u in [0, 1] (ω = u·ω_max, T = k_f·ω²) for the request."""
        k_f = self.k_f
        w_max = self.omega_max
        t_max = self.max_rotor_thrust_n
        mid, yaw, s_yaw = self._fit(thrust_n, torque_x, torque_y, torque_z)
        out = []
        for m, d in zip(mid, yaw, strict=True):
            t = m + s_yaw * d  # min(max(t, 0.0), t_max), NaN kept as the builtins keep it
            if t < 0.0:
                t = 0.0
            if t_max < t:
                t = t_max
            u = math.sqrt(t / k_f) / w_max
            out.append(1.0 if u > 1.0 else u)
        return out

    def _fit(
        self, thrust_n: float, torque_x: float, torque_y: float, torque_z: float
    ) -> tuple[list[float], list[float], float]:
        """The rotors' thrusts with roll/pitch scaled to fit, their yaw shares, the yaw scale
        that fits. Each scale is the largest s in [0, 1] with every rotor's b + s·d inside
        [0, t_max] (where b itself is), found in the pass over the rotors that makes b and d."""
        t_max = self.max_rotor_thrust_n
        thrust_n = min(max(thrust_n, 0.0), t_max * self.rotor_count)
        base = []
        rp = []
        yaw = []
        s = 1.0
        for r0, r1, r2, r3 in self._rows:
            b = r0 * thrust_n
            d = r1 * torque_x + r2 * torque_y
            base.append(b)
            rp.append(d)
            yaw.append(r3 * torque_z)
            if d > 0.0:  # inline, not a call per rotor: this runs every tick for every rotor
                room = t_max - b
                if room < s * d:
                    s = max(room, 0.0) / d
            elif d < 0.0 and b < -s * d:
                s = max(b, 0.0) / -d
        mid = []
        s_yaw = 1.0
        for b, d, y in zip(base, rp, yaw, strict=True):
            m = b + s * d
            mid.append(m)
            if y > 0.0:
                room = t_max - m
                if room < s_yaw * y:
                    s_yaw = max(room, 0.0) / y
            elif y < 0.0 and m < -s_yaw * y:
                s_yaw = max(m, 0.0) / -y
        return mid, yaw, s_yaw
