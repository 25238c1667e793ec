"""Vehicle types are data: one TOML file each under ``swarmbus/vehicles/``.

Both the physics (mass, inertia, rotors, drag, collision shape) and the autopilot (mixer from
the rotor layout, gains, limits) read the same file, so it lives in the shared contract.
Adding a type is adding a file. ``kind`` says which physics and which controller fly it:
``multirotor`` (rotors, the cascaded controller) or ``fixed_wing`` (the ``[fixed_wing]``
table: Beard & McLain's aerodynamic model and PX4's fixed-wing parameters).
"""

from __future__ import annotations

import math
import tomllib
from functools import cache
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from swarmbus.errors import PlumeswarmError

PositiveF = Annotated[float, msgspec.Meta(gt=0.0, le=1e6)]
FiniteF = Annotated[float, msgspec.Meta(ge=-1e6, le=1e6)]
NonNegF = Annotated[float, msgspec.Meta(ge=0.0, le=1e6)]
Vec3F = tuple[FiniteF, FiniteF, FiniteF]

VEHICLES_DIR = Path(__file__).with_name("vehicles")


class Rotor(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """A rotor at ``position_m`` (body FLU) spinning counter-clockwise (+1) or clockwise (-1)
    seen from above; its reaction torque on the body is opposite to its spin."""

    position_m: Vec3F
    spin: Literal[1, -1]


class Gains(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Cascaded controller gains (position → velocity → attitude → rate) and limits."""

    pos_p: Vec3F = (1.0, 1.0, 1.5)
    vel_p: Vec3F = (2.0, 2.0, 4.0)
    vel_i: Vec3F = (0.2, 0.2, 1.0)
    vel_d: Vec3F = (0.0, 0.0, 0.0)
    att_p: Vec3F = (6.0, 6.0, 3.0)
    rate_p: Vec3F = (0.15, 0.15, 0.1)
    rate_i: Vec3F = (0.05, 0.05, 0.02)
    rate_d: Vec3F = (0.003, 0.003, 0.0)
    max_tilt_deg: PositiveF = 35.0
    max_speed_xy_m_s: PositiveF = 10.0
    max_speed_up_m_s: PositiveF = 3.0
    max_speed_down_m_s: PositiveF = 1.5
    max_yaw_rate_deg_s: PositiveF = 90.0


class FixedWingParams(
    msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True, rename="upper"
):
    """PX4's fixed-wing parameters, by their PX4 names in the file (``FW_AIRSPD_TRIM`` …).

    Speeds are airspeeds (m/s), angles degrees, time constants seconds; throttle 0..1.
    """

    fw_airspd_min: PositiveF = 18.0  # stall protection: no speed setpoint below this
    fw_airspd_trim: PositiveF = 22.0
    fw_airspd_max: PositiveF = 30.0
    fw_t_clmb_max: PositiveF = 5.0  # max climb rate, m/s
    fw_t_sink_min: PositiveF = 2.0  # sink rate at minimum throttle, m/s
    fw_t_sink_max: PositiveF = 5.0  # max sink rate, m/s
    fw_t_time_const: PositiveF = 5.0  # TECS time constant, s
    fw_t_thr_damp: NonNegF = 0.1
    fw_t_integ_gain: NonNegF = 0.1
    fw_t_spdweight: Annotated[float, msgspec.Meta(ge=0.0, le=2.0)] = 1.0
    fw_thr_min: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.0
    fw_thr_max: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 1.0
    fw_thr_trim: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.35
    fw_p_lim_max: PositiveF = 25.0  # pitch setpoint limits, deg
    fw_p_lim_min: FiniteF = -20.0
    fw_r_lim: PositiveF = 35.0  # roll setpoint limit, deg
    fw_r_tc: PositiveF = 0.4  # roll attitude time constant, s
    fw_p_tc: PositiveF = 0.4  # pitch attitude time constant, s
    fw_rr_p: NonNegF = 0.1  # roll rate P, surface travel per rad/s
    fw_rr_i: NonNegF = 0.1
    fw_rr_ff: NonNegF = 0.4
    fw_pr_p: NonNegF = 0.15
    fw_pr_i: NonNegF = 0.2
    fw_pr_ff: NonNegF = 0.3
    fw_yr_p: NonNegF = 0.1  # yaw damper
    fw_psp_off: FiniteF = 0.0  # pitch setpoint offset (level flight), deg
    fw_t_ptch_damp: NonNegF = 0.1
    # elevator trim (travel, Beard's sign: negative pitches up) at FW_AIRSPD_TRIM, and its
    # increments at FW_AIRSPD_MIN and FW_AIRSPD_MAX
    trim_pitch: Annotated[float, msgspec.Meta(ge=-1.0, le=1.0)] = 0.0
    fw_dtrim_p_vmin: Annotated[float, msgspec.Meta(ge=-1.0, le=1.0)] = 0.0
    fw_dtrim_p_vmax: Annotated[float, msgspec.Meta(ge=-1.0, le=1.0)] = 0.0
    nav_l1_period: PositiveF = 20.0  # s
    nav_l1_damping: PositiveF = 0.75
    nav_loiter_rad: PositiveF = 80.0  # m
    nav_acc_rad: PositiveF = 20.0  # waypoint acceptance radius, m
    fw_clmbout_diff: PositiveF = 10.0  # take-off: climb out at max pitch below this height, m
    fw_tko_pitch_min: FiniteF = 10.0  # take-off: pitch at least this from rotation on, deg
    fw_lnd_ang: PositiveF = 5.0  # landing glide slope, deg
    fw_lnd_flalt: PositiveF = 3.0  # flare altitude, m
    fw_lnd_airspd_sc: PositiveF = 1.2  # approach airspeed = this * FW_AIRSPD_MIN
    fw_lnd_fl_pmin: FiniteF = 2.5  # flare pitch min, deg
    fw_lnd_fl_pmax: FiniteF = 15.0  # flare pitch max, deg
    fw_lnd_fl_sink: PositiveF = 0.5  # sink rate in the flare, m/s (plumeswarm's name)


class FixedWing(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Beard & McLain's fixed-wing model (Small Unmanned Aircraft, 2012, ch. 4): geometry,
    the lift curve with its blended flat-plate stall, the drag polar, stability, damping and
    control derivatives (body frame forward-right-down, angles in radians, rates normalised by
    ``b/2Va`` or ``c/2Va``), the propeller, control-surface travel and PX4's parameters."""

    wing_area_m2: PositiveF
    span_m: PositiveF
    chord_m: PositiveF
    oswald_e: PositiveF
    air_density_kg_m3: PositiveF
    # longitudinal
    c_l_0: FiniteF
    c_l_alpha: FiniteF
    c_l_q: FiniteF
    c_l_delta_e: FiniteF
    c_d_p: NonNegF  # parasitic drag: C_D = C_D_p + C_L_lin^2 / (pi e AR)
    c_d_q: FiniteF
    c_d_delta_e: FiniteF
    c_m_0: FiniteF
    c_m_alpha: FiniteF
    c_m_q: FiniteF
    c_m_delta_e: FiniteF
    stall_blend_m: PositiveF  # M: sharpness of the blend to the flat plate
    stall_alpha0_rad: PositiveF  # alpha_0: where the blend is half way
    # lateral
    c_y_0: FiniteF
    c_y_beta: FiniteF
    c_y_p: FiniteF
    c_y_r: FiniteF
    c_y_delta_a: FiniteF
    c_y_delta_r: FiniteF
    c_ell_0: FiniteF
    c_ell_beta: FiniteF
    c_ell_p: FiniteF
    c_ell_r: FiniteF
    c_ell_delta_a: FiniteF
    c_ell_delta_r: FiniteF
    c_n_0: FiniteF
    c_n_beta: FiniteF
    c_n_p: FiniteF
    c_n_r: FiniteF
    c_n_delta_a: FiniteF
    c_n_delta_r: FiniteF
    # propeller: F = rho/2 S_prop C_prop ((k_motor dt)^2 - Va^2); torque -k_Tp (k_Omega dt)^2
    prop_area_m2: PositiveF
    c_prop: PositiveF
    k_motor_m_s: PositiveF
    k_t_p: NonNegF
    k_omega_rad_s: NonNegF
    # full travel of aileron, elevator, rudder (deg): actuator 0..1 maps to -max..+max
    max_deflection_deg: Vec3F
    params: FixedWingParams = FixedWingParams()

    @property
    def aspect_ratio(self) -> float:
        return self.span_m**2 / self.wing_area_m2


# The physics' gravity (sim_world), for the stall speed.
GRAVITY_M_S2 = 9.81


def stall_blend(fw: FixedWing, alpha: float) -> float:
    """Beard's sigma(alpha), eq. 4.10: 0 on the linear lift curve, 1 on the flat plate."""
    m, a0 = fw.stall_blend_m, fw.stall_alpha0_rad
    e_minus = math.exp(-m * (alpha - a0))
    e_plus = math.exp(m * (alpha + a0))
    return (1.0 + e_minus + e_plus) / ((1.0 + e_minus) * (1.0 + e_plus))


def lift_coefficient(fw: FixedWing, alpha: float) -> float:
    """C_L(alpha), eq. 4.9: the blended linear / flat-plate lift curve (the physics' own)."""
    s = stall_blend(fw, alpha)
    sa = math.sin(alpha)
    plate = 2.0 * math.copysign(1.0, alpha) * sa * sa * math.cos(alpha)
    return (1.0 - s) * (fw.c_l_0 + fw.c_l_alpha * alpha) + s * plate


# Fixed-wing actuator channels (ActuatorCommand.rotor_commands): throttle, then the surfaces.
FW_THROTTLE, FW_AILERON, FW_ELEVATOR, FW_RUDDER = 0, 1, 2, 3
FW_CHANNELS = 4


class VehicleType(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    name: str
    description: str = ""
    kind: Literal["multirotor", "fixed_wing"] = "multirotor"
    mass_kg: PositiveF
    inertia_kg_m2: Vec3F  # principal moments ixx, iyy, izz (body FLU)
    # multirotor: at least 3 (checked below); a fixed wing has none (its propeller is in
    # ``fixed_wing``)
    rotors: Annotated[list[Rotor], msgspec.Meta(max_length=16)] = []
    thrust_coeff_n_per_rad2_s2: NonNegF = 0.0  # thrust = k_f * omega^2 (multirotor: > 0)
    torque_coeff_nm_per_rad2_s2: NonNegF = 0.0  # reaction torque = k_m * omega^2 (> 0)
    max_rotor_speed_rad_s: NonNegF = 0.0  # (multirotor: > 0)
    motor_time_constant_s: NonNegF
    linear_drag_n_per_m_s: Vec3F = (0.0, 0.0, 0.0)  # body-axis linear drag against the air
    collision_half_extents_m: Vec3F  # box
    gains: Gains = Gains()
    fixed_wing: FixedWing | None = None

    def __post_init__(self) -> None:
        if self.kind == "multirotor":
            if len(self.rotors) < 3:
                raise ValueError("a multirotor needs at least 3 rotors - at `$.rotors`")
            for key in (
                "thrust_coeff_n_per_rad2_s2",
                "torque_coeff_nm_per_rad2_s2",
                "max_rotor_speed_rad_s",
            ):
                if getattr(self, key) <= 0.0:
                    raise ValueError(f"a multirotor needs {key} > 0 - at `$.{key}`")
            if self.fixed_wing is not None:
                raise ValueError("a multirotor has no [fixed_wing] table - at `$.fixed_wing`")
        else:
            if self.fixed_wing is None:
                raise ValueError("kind fixed_wing needs a [fixed_wing] table - at `$.fixed_wing`")
            if self.rotors:
                raise ValueError("a fixed wing has no [[rotors]] - at `$.rotors`")

    @property
    def actuator_count(self) -> int:
        """Entries of this type's ``ActuatorCommand.rotor_commands``."""
        return FW_CHANNELS if self.fixed_wing is not None else len(self.rotors)

    @property
    def stall_speed_m_s(self) -> float:
        """A fixed wing's level-flight stall speed (airspeed, m/s) at its mass: lift equals
        weight at the peak of the lift curve (sampled every milliradian up to 90°); 0 for a
        multirotor."""
        fw = self.fixed_wing
        if fw is None:
            return 0.0
        peak = max(lift_coefficient(fw, k / 1000.0) for k in range(1, 1571))
        weight = self.mass_kg * GRAVITY_M_S2
        return math.sqrt(2.0 * weight / (fw.air_density_kg_m3 * fw.wing_area_m2 * peak))

    @property
    def max_total_thrust_n(self) -> float:
        return len(self.rotors) * self.thrust_coeff_n_per_rad2_s2 * self.max_rotor_speed_rad_s**2


class VehicleTypeError(PlumeswarmError, ValueError):
    pass


def available_types() -> list[str]:
    return sorted(p.stem for p in VEHICLES_DIR.glob("*.toml"))


@cache
def load_vehicle_type(name: str) -> VehicleType:
    """Load ``swarmbus/vehicles/<name>.toml``; raise :class:`VehicleTypeError` clearly."""
    path = VEHICLES_DIR / f"{name}.toml"
    if not path.is_file():
        raise VehicleTypeError(
            f"unknown vehicle type {name!r}; available: {', '.join(available_types())}"
        )
    try:
        raw = tomllib.loads(path.read_text())
        return msgspec.convert(raw, VehicleType)
    except (tomllib.TOMLDecodeError, msgspec.ValidationError) as exc:
        raise VehicleTypeError(f"{path}: {exc}") from None
