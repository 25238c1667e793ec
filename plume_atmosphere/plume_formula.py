"""The steady Gaussian plume equation as one plain vectorised function (no mixing lid).

    C = Q/(2π u σy σz) · exp(−y²/2σy²) · [exp(−(z−H)²/2σz²) + exp(−(z+H)²/2σz²)]

in the plume frame (x downwind of the source, y crosswind to the left, z height), 0 for x ≤ 0
(Beychok, *Fundamentals of Stack Gas Dispersion*, 4th ed., 2005, ch. 8). It is the forward
model of behaviours that estimate a source (they may not import the plume service); the
plume service evaluates the same equation with its own optimised kernel and a mixing lid.
Every argument broadcasts, so one call evaluates many candidate sources (particles) at once.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from plume_atmosphere.dispersion import DispersionCurves

FloatArray = npt.NDArray[np.float64]


def downwind_unit(wind_from_deg: float) -> tuple[float, float]:
    """The ENU unit vector the wind blows toward (``wind_from_deg`` meteorological)."""
    toward = math.radians(wind_from_deg + 180.0)
    return math.sin(toward), math.cos(toward)


def plume_frame(
    east_m: npt.ArrayLike,
    north_m: npt.ArrayLike,
    source_east_m: npt.ArrayLike,
    source_north_m: npt.ArrayLike,
    wind_from_deg: float,
) -> tuple[FloatArray, FloatArray]:
    """Downwind x and crosswind y (to the left of the wind) of points relative to sources."""
    ux, uy = downwind_unit(wind_from_deg)
    de = np.subtract(east_m, source_east_m, dtype=np.float64)
    dn = np.subtract(north_m, source_north_m, dtype=np.float64)
    return de * ux + dn * uy, dn * ux - de * uy


def gaussian_plume_g_m3(
    x_down_m: npt.ArrayLike,
    y_cross_m: npt.ArrayLike,
    z_m: npt.ArrayLike,
    release_rate_g_s: npt.ArrayLike,
    wind_speed_m_s: float,
    release_height_m: float,
    curves: DispersionCurves,
) -> FloatArray:
    """Concentration (g/m³) at plume-frame points; exactly 0 at and upwind of the source."""
    x = np.asarray(x_down_m, dtype=np.float64)
    y, z, q = np.broadcast_arrays(
        np.asarray(y_cross_m, dtype=np.float64),
        np.asarray(z_m, dtype=np.float64),
        np.asarray(release_rate_g_s, dtype=np.float64),
    )
    x, y, z, q = np.broadcast_arrays(x, y, z, q)
    downwind = x > 0.0
    out = np.zeros(x.shape, dtype=np.float64)
    if not downwind.any():
        return out
    xd, yd, zd = x[downwind], y[downwind], z[downwind]
    sigma_y, sigma_z = curves.sigmas(xd)
    with np.errstate(under="ignore"):
        crosswind = np.exp(-0.5 * (yd / sigma_y) ** 2)
        vertical = np.exp(-0.5 * ((zd - release_height_m) / sigma_z) ** 2) + np.exp(
            -0.5 * ((zd + release_height_m) / sigma_z) ** 2
        )
    scale = q[downwind] / (2.0 * math.pi * wind_speed_m_s)
    out[downwind] = scale * crosswind * vertical / (sigma_y * sigma_z)
    return out
