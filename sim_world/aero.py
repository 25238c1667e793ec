"""Fixed-wing aerodynamics and propeller: Beard & McLain's model (Small Unmanned Aircraft,
2012, ch. 4, eqs. 4.6-4.19), forces and moments from the air-relative velocity.

The model is written in Beard's body frame (x forward, y right, z down); plumeswarm's bodies
are FLU, so inputs are converted on the way in and the wrench on the way out. Plain scalar
maths: this runs per vehicle and physics substep.

- airspeed ``Va = |v - wind|``, angle of attack ``alpha = atan2(w, u)``, sideslip
  ``beta = asin(v / Va)`` (``u, v, w``: the air-relative velocity in the body frame);
- lift ``C_L(alpha) = (1 - s) (C_L0 + C_La alpha) + s 2 sign(alpha) sin^2(alpha) cos(alpha)``
  with the blend ``s(alpha)`` of eq. 4.10 (``M``, ``alpha_0``): the linear lift curve below
  stall, the flat plate beyond; drag polar ``C_D = C_Dp + (C_L0 + C_La alpha)^2 / (pi e AR)``;
- lift and drag rotated into body x and z (eq. 4.19), side force, roll, pitch and yaw moments
  with their sideslip, damping (``p b / 2Va``, ``q c / 2Va``, ``r b / 2Va``) and control
  derivatives;
- propeller thrust ``rho/2 S_prop C_prop ((k_motor dt)^2 - Va^2)`` along body x (negative: the
  windmilling propeller brakes) and its torque ``-k_Tp (k_Omega dt)^2`` about body x.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from swarmbus.vehicle_types import FixedWing, lift_coefficient

# Below this airspeed the angles are undefined: no aerodynamic force (the propeller still pulls).
MIN_AIRSPEED_M_S = 0.1

Wrench = tuple[float, float, float, float, float, float]


def drag_coefficient(fw: FixedWing, alpha: float) -> float:
    """C_D(alpha), eq. 4.11: parasitic drag plus the induced drag of the linear lift."""
    cl = fw.c_l_0 + fw.c_l_alpha * alpha
    return fw.c_d_p + cl * cl / (math.pi * fw.oswald_e * fw.aspect_ratio)


def propeller_thrust(fw: FixedWing, throttle: float, airspeed: float) -> float:
    """Beard's propeller, eq. 4.18: thrust along body x, N."""
    return (
        0.5
        * fw.air_density_kg_m3
        * fw.prop_area_m2
        * fw.c_prop
        * ((fw.k_motor_m_s * throttle) ** 2 - airspeed * airspeed)
    )


def fixed_wing_wrench(
    fw: FixedWing,
    throttle: float,
    surfaces_rad: Sequence[float],
    air_body_flu: tuple[float, float, float],
    rates_body_flu: tuple[float, float, float],
) -> Wrench:
    """Body-FLU force (N) and moment (N m) of the air and the propeller.

    ``surfaces_rad``: aileron, elevator, rudder deflections (Beard's signs: positive elevator
    pitches the nose down, positive aileron rolls left, positive rudder yaws left).
    ``air_body_flu``: the body's velocity relative to the air, body FLU; ``rates_body_flu``:
    the body rates, body FLU.
    """
    u, v, w = air_body_flu[0], -air_body_flu[1], -air_body_flu[2]
    p, q, r = rates_body_flu[0], -rates_body_flu[1], -rates_body_flu[2]
    va = math.sqrt(u * u + v * v + w * w)
    prop = propeller_thrust(fw, throttle, va)
    roll_prop = -fw.k_t_p * (fw.k_omega_rad_s * throttle) ** 2
    if va < MIN_AIRSPEED_M_S:
        return prop, 0.0, 0.0, roll_prop, 0.0, 0.0
    da, de, dr = surfaces_rad
    alpha = math.atan2(w, u)
    beta = math.asin(max(-1.0, min(1.0, v / va)))
    ca, sa = math.cos(alpha), math.sin(alpha)
    cl = lift_coefficient(fw, alpha)
    cd = drag_coefficient(fw, alpha)
    qbar = 0.5 * fw.air_density_kg_m3 * va * va * fw.wing_area_m2
    b, c = fw.span_m, fw.chord_m
    pn, qn, rn = b * p / (2.0 * va), c * q / (2.0 * va), b * r / (2.0 * va)
    # lift and drag (stability axes) rotated into body x and z, eq. 4.19
    cx = -cd * ca + cl * sa
    cxq = -fw.c_d_q * ca + fw.c_l_q * sa
    cxde = -fw.c_d_delta_e * ca + fw.c_l_delta_e * sa
    cz = -cd * sa - cl * ca
    czq = -fw.c_d_q * sa - fw.c_l_q * ca
    czde = -fw.c_d_delta_e * sa - fw.c_l_delta_e * ca
    fx = qbar * (cx + cxq * qn + cxde * de) + prop
    fy = qbar * (
        fw.c_y_0
        + fw.c_y_beta * beta
        + fw.c_y_p * pn
        + fw.c_y_r * rn
        + fw.c_y_delta_a * da
        + fw.c_y_delta_r * dr
    )
    fz = qbar * (cz + czq * qn + czde * de)
    ell = (
        qbar
        * b
        * (
            fw.c_ell_0
            + fw.c_ell_beta * beta
            + fw.c_ell_p * pn
            + fw.c_ell_r * rn
            + fw.c_ell_delta_a * da
            + fw.c_ell_delta_r * dr
        )
    )
    m = qbar * c * (fw.c_m_0 + fw.c_m_alpha * alpha + fw.c_m_q * qn + fw.c_m_delta_e * de)
    n = (
        qbar
        * b
        * (
            fw.c_n_0
            + fw.c_n_beta * beta
            + fw.c_n_p * pn
            + fw.c_n_r * rn
            + fw.c_n_delta_a * da
            + fw.c_n_delta_r * dr
        )
    )
    # back to FLU: y and z change sign
    return fx, -fy, -fz, ell + roll_prop, -m, -n
