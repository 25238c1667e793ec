"""Vehicle types are data: one TOML file each under ``swarmbus/vehicles/``.

Both the physics (mass, inertia, rotors, drag, collision shape) and the autopilot (mixer from
the rotor layout, gains, limits) read the same file, so it lives in the shared contract.
Adding a type is adding a file.
"""

from __future__ import annotations

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


class VehicleType(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    name: str
    description: str = ""
    mass_kg: PositiveF
    inertia_kg_m2: Vec3F  # principal moments ixx, iyy, izz (body FLU)
    rotors: Annotated[list[Rotor], msgspec.Meta(min_length=3, max_length=16)]
    thrust_coeff_n_per_rad2_s2: PositiveF  # thrust = k_f * omega^2
    torque_coeff_nm_per_rad2_s2: PositiveF  # reaction torque = k_m * omega^2
    max_rotor_speed_rad_s: PositiveF
    motor_time_constant_s: NonNegF
    linear_drag_n_per_m_s: Vec3F  # body-axis linear drag against the air velocity
    collision_half_extents_m: Vec3F  # box
    gains: Gains = Gains()

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
