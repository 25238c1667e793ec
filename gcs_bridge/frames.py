"""Frame conversions between the bus (world ENU, body FLU) and MAVLink (local NED, body FRD).

World: ENU (x east, y north, z up) → NED (x north, y east, z down).
Body: FLU (x forward, y left, z up) → FRD (x forward, y right, z down).
Geodetic conversions use pymap3d around the scenario origin.
"""

from __future__ import annotations

import math

import pymap3d

from swarmbus.scenario import Origin

Vec3 = tuple[float, float, float]


def enu_to_ned(v: Vec3) -> Vec3:
    return (v[1], v[0], -v[2])


def ned_to_enu(v: Vec3) -> Vec3:
    return (v[1], v[0], -v[2])


def flu_to_frd(v: Vec3) -> Vec3:
    """Body vectors and body rates: y and z flip sign."""
    return (v[0], -v[1], -v[2])


def euler_ned_frd(q_xyzw: tuple[float, float, float, float]) -> Vec3:
    """(roll, pitch, yaw) in radians, MAVLink convention, from a body FLU → world ENU quaternion.

    With R the FLU→ENU rotation matrix, the FRD→NED matrix is ``A·R·B`` (A swaps x/y and
    negates z, B negates y and z); its ZYX Euler angles reduce to the entries of R used below.
    Yaw is in (-π, π], 0 = north, positive clockwise seen from above.
    """
    x, y, z, w = q_xyzw
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n < 1e-12:
        return (0.0, 0.0, 0.0)
    x, y, z, w = x / n, y / n, z / n, w / n
    r00 = 1.0 - 2.0 * (y * y + z * z)
    r10 = 2.0 * (x * y + z * w)
    r20 = 2.0 * (x * z - y * w)
    r21 = 2.0 * (y * z + x * w)
    r22 = 1.0 - 2.0 * (x * x + y * y)
    roll = math.atan2(r21, r22)
    pitch = math.asin(max(-1.0, min(1.0, r20)))
    yaw = math.atan2(r00, r10)
    return (roll, pitch, yaw)


def heading_deg(yaw_rad: float) -> float:
    """A compass heading in [0, 360) from a NED yaw."""
    return math.degrees(yaw_rad) % 360.0


def course_deg(velocity_enu: Vec3) -> float:
    """Course over ground in [0, 360) (0 = north), from an ENU velocity."""
    return math.degrees(math.atan2(velocity_enu[0], velocity_enu[1])) % 360.0


def enu_yaw_deg_of_heading(heading: float) -> float:
    """Our ENU yaw (0 = east, counter-clockwise) of a compass heading (0 = north, clockwise)."""
    return (90.0 - heading + 180.0) % 360.0 - 180.0


def enu_to_geodetic(enu: Vec3, origin: Origin) -> Vec3:
    """(lat deg, lon deg, alt m AMSL) of an ENU point."""
    lat, lon, alt = pymap3d.enu2geodetic(
        enu[0], enu[1], enu[2], origin.lat_deg, origin.lon_deg, origin.alt_m
    )
    return (float(lat), float(lon), float(alt))


def geodetic_to_enu(lat_deg: float, lon_deg: float, alt_m: float, origin: Origin) -> Vec3:
    e, n, u = pymap3d.geodetic2enu(
        lat_deg, lon_deg, alt_m, origin.lat_deg, origin.lon_deg, origin.alt_m
    )
    return (float(e), float(n), float(u))
