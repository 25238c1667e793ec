"""The vehicle parameters the gateway exposes: a small, real set with PX4's names.

Values start from the scenario (failsafe section and vehicle type) and are replaced by the
autopilot's own values when it answers ``GetParams``; ``PARAM_SET`` goes to the autopilot as
``SetParam`` and the table keeps what the autopilot confirmed. Two parameters act in the
gateway itself and live here when the autopilot does not know them: MIS_TAKEOFF_ALT (takeoff
commands without an altitude) and MPC_XY_CRUISE (speed of MAVLink missions and go-to).
A fixed wing shows, instead of MPC_XY_CRUISE, its type's ``[fixed_wing.params]`` (FW_AIRSPD_*,
NAV_LOITER_RAD, ...), which its autopilot flies by.
PARAM_VALUE uses PX4's bytewise encoding: an INT32 parameter's bits travel in the float field.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

import msgspec
import msgspec.inspect

from gcs_bridge.dialect import mavlink
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import COM_OBL_ACT_CODES, NAV_DLL_ACT_CODES
from swarmbus.scenario import Failsafe
from swarmbus.vehicle_types import FixedWingParams, VehicleType

REAL32 = int(mavlink.MAV_PARAM_TYPE_REAL32)
INT32 = int(mavlink.MAV_PARAM_TYPE_INT32)


class ParamError(PlumeswarmError, ValueError):
    """A PARAM_SET the gateway refuses before asking the autopilot (field and reason)."""

    def __init__(self, name: str, reason: str) -> None:
        self.name = name
        self.reason = reason
        super().__init__(f"{name}: {reason}")


@dataclass(frozen=True)
class ParamSpec:
    name: str
    param_type: int
    min_value: float
    max_value: float
    default: Callable[[Failsafe, VehicleType], float]
    description: str
    gateway_side: bool = False  # the gateway itself uses it (kept here if the autopilot can't)


SPECS: tuple[ParamSpec, ...] = (
    ParamSpec(
        "MIS_TAKEOFF_ALT",
        REAL32,
        0.5,
        1000.0,
        lambda f, t: f.takeoff_altitude_m,
        "takeoff altitude above home (m); used when a takeoff command gives none",
        gateway_side=True,
    ),
    ParamSpec(
        "RTL_RETURN_ALT",
        REAL32,
        0.5,
        1000.0,
        lambda f, t: f.rtl_altitude_m,
        "return-to-launch altitude above home (m)",
    ),
    ParamSpec(
        "NAV_DLL_ACT",
        INT32,
        0,
        3,
        lambda f, t: NAV_DLL_ACT_CODES[f.datalink_loss_action],
        "data-link-loss action: 0 none, 1 hold, 2 RTL, 3 land",
    ),
    ParamSpec(
        "COM_DL_LOSS_T",
        INT32,
        1,
        300,
        lambda f, t: round(f.datalink_timeout_s),
        "data-link-loss timeout (s of sim time)",
    ),
    ParamSpec(
        "COM_OBL_ACT",
        INT32,
        0,
        2,
        lambda f, t: COM_OBL_ACT_CODES[f.offboard_loss_action],
        "offboard-loss action (PX4's codes): 0 land, 1 hold, 2 RTL",
    ),
    ParamSpec(
        "COM_OF_LOSS_T",
        REAL32,
        0.05,
        60.0,
        lambda f, t: f.offboard_timeout_s,
        "offboard setpoint-stream timeout (s)",
    ),
    ParamSpec(
        "GF_MAX_VER_DIST",
        REAL32,
        0.0,
        10000.0,
        lambda f, t: f.geofence_max_altitude_m,
        "geofence: maximum altitude above home (m); 0: off",
    ),
    ParamSpec(
        "GF_MAX_HOR_DIST",
        REAL32,
        0.0,
        100000.0,
        lambda f, t: f.geofence_max_distance_m,
        "geofence: maximum horizontal distance from home (m); 0: off",
    ),
    # follow-me (PX4's names and defaults), used by the gateway for FOLLOW_TARGET
    ParamSpec(
        "FLW_TGT_HT",
        REAL32,
        8.0,
        100.0,
        lambda f, t: 8.0,
        "follow-me height above home (m)",
        gateway_side=True,
    ),
    ParamSpec(
        "FLW_TGT_DST",
        REAL32,
        1.0,
        100.0,
        lambda f, t: 8.0,
        "follow-me distance from the target (m)",
        gateway_side=True,
    ),
    ParamSpec(
        "FLW_TGT_FA",
        REAL32,
        -180.0,
        180.0,
        lambda f, t: 180.0,
        "follow-me angle from the target's heading (deg; 180 behind)",
        gateway_side=True,
    ),
    ParamSpec(
        "FLW_TGT_RS",
        REAL32,
        0.0,
        1.0,
        lambda f, t: 0.1,
        "follow-me responsiveness (kept, not used)",
        gateway_side=True,
    ),
    ParamSpec(
        "FLW_TGT_ALT_M",
        INT32,
        0,
        2,
        lambda f, t: 0,
        "follow-me altitude mode (0: above home; kept)",
        gateway_side=True,
    ),
    ParamSpec(
        "FLW_TGT_MAX_VEL",
        REAL32,
        0.0,
        20.0,
        lambda f, t: 5.0,
        "follow-me orbit speed (m/s; kept, not used)",
        gateway_side=True,
    ),
    ParamSpec(
        "MPC_XY_CRUISE",
        REAL32,
        0.1,
        50.0,
        lambda f, t: min(5.0, t.gains.max_speed_xy_m_s),
        "horizontal cruise speed of missions and go-to sent through MAVLink (m/s)",
        gateway_side=True,
    ),
)


# MPC_XY_CRUISE is a multirotor's: a fixed wing flies MAVLink missions and go-to at
# FW_AIRSPD_TRIM (a speed of 0 asks the autopilot for it), as PX4's planes do.
MULTIROTOR_ONLY = frozenset({"MPC_XY_CRUISE"})


def _fixed_wing_spec(field: msgspec.inspect.Field) -> ParamSpec:
    """A PX4 fixed-wing parameter of the vehicle type's ``[fixed_wing.params]``, its range
    the type's own bounds (the autopilot checks the rest: stall speed, MIN <= TRIM <= MAX)."""
    ftype = field.type
    assert isinstance(ftype, msgspec.inspect.FloatType)
    low = ftype.ge if ftype.ge is not None else ftype.gt
    high = ftype.le if ftype.le is not None else ftype.lt
    name = field.encode_name

    def default(f: Failsafe, t: VehicleType) -> float:
        assert t.fixed_wing is not None
        return float(getattr(t.fixed_wing.params, field.name))

    return ParamSpec(
        name,
        REAL32,
        -math.inf if low is None else float(low),
        math.inf if high is None else float(high),
        default,
        f"fixed-wing {name} (the vehicle type's [fixed_wing.params])",
    )


def _fixed_wing_specs() -> tuple[ParamSpec, ...]:
    info = msgspec.inspect.type_info(FixedWingParams)
    assert isinstance(info, msgspec.inspect.StructType)
    return tuple(_fixed_wing_spec(field) for field in info.fields)


FIXED_WING_SPECS = (
    *(s for s in SPECS if s.name not in MULTIROTOR_ONLY),
    *_fixed_wing_specs(),
)


def specs_for(vehicle_type: VehicleType) -> tuple[ParamSpec, ...]:
    """The parameters a vehicle of this type shows: a multirotor's, or a fixed wing's."""
    return FIXED_WING_SPECS if vehicle_type.fixed_wing is not None else SPECS


def float_bits_of_int(value: int) -> float:
    """PX4's bytewise encoding: the int32's bytes read as a float32."""
    return float(struct.unpack("<f", struct.pack("<i", int(value)))[0])


def int_of_float_bits(value: float) -> int:
    return int(struct.unpack("<i", struct.pack("<f", value))[0])


class ParamTable:
    """One vehicle's parameters: fixed order (param_index), current values, and provenance."""

    def __init__(self, failsafe: Failsafe, vehicle_type: VehicleType) -> None:
        self.specs = specs_for(vehicle_type)
        self._index = {s.name: i for i, s in enumerate(self.specs)}
        self._values: dict[str, float] = {
            s.name: float(s.default(failsafe, vehicle_type)) for s in self.specs
        }
        self.backed: set[str] = set()  # names the autopilot has confirmed

    @property
    def count(self) -> int:
        return len(self.specs)

    def index_of(self, name: str) -> int | None:
        return self._index.get(name)

    def spec(self, name: str) -> ParamSpec | None:
        i = self._index.get(name)
        return self.specs[i] if i is not None else None

    def value(self, name: str) -> float:
        return self._values[name]

    @property
    def cruise_m_s(self) -> float:
        """Speed of MAVLink missions and go-to: MPC_XY_CRUISE, or 0 (the autopilot's own:
        FW_AIRSPD_TRIM) for a fixed wing, which has no MPC_XY_CRUISE."""
        return self._values.get("MPC_XY_CRUISE", 0.0)

    def wire_value(self, name: str) -> float:
        """The float that goes in PARAM_VALUE.param_value (bytewise for integers)."""
        spec = self.specs[self._index[name]]
        v = self._values[name]
        return float_bits_of_int(round(v)) if spec.param_type == INT32 else v

    def decode_set(self, name: str, wire_value: float) -> float:
        """The value a PARAM_SET asks for, checked (finite, in range); :class:`ParamError` else.

        Integer parameters arrive bytewise (QGC, MAVSDK with PX4) or as a plain float cast
        (MAVProxy): an integral float in range is taken as is, anything else as bytewise.
        """
        spec = self.spec(name)
        if spec is None:
            raise ParamError(name, "unknown parameter")
        if spec.param_type == INT32:
            if math.isfinite(wire_value) and wire_value == int(wire_value):
                value = float(int(wire_value))
            else:
                value = float(int_of_float_bits(wire_value))
        else:
            if not math.isfinite(wire_value):
                raise ParamError(name, f"value {wire_value} is not finite")
            value = float(wire_value)
        if not spec.min_value <= value <= spec.max_value:
            raise ParamError(
                name, f"value {value:g} outside [{spec.min_value:g}, {spec.max_value:g}]"
            )
        return value

    def set(self, name: str, value: float, backed: bool) -> None:
        if name in self._values:
            self._values[name] = float(value)
            if backed:
                self.backed.add(name)

    def merge_from_autopilot(self, params: dict[str, float]) -> None:
        """Take the autopilot's values for every name we expose (the rest stay scenario-based)."""
        for name, value in params.items():
            if name in self._values and math.isfinite(value):
                self.set(name, value, backed=True)
