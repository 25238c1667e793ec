"""The steady Gaussian plume equation, the one place it is written.

In the plume frame (x downwind of the source, y crosswind to the left, z height above ground)

    C = Q/(2π u σy σz) · exp(−y²/2σy²) · [exp(−(z−H)²/2σz²) + exp(−(z+H)²/2σz²)]

(ground reflection), 0 for x ≤ 0 (Beychok, *Fundamentals of Stack Gas Dispersion*, 4th ed.,
2005, ch. 8). With a mixing height L the lid reflects too, and the bracket becomes the sum over
the images ±H + 2kL, k ∈ ℤ; it is evaluated as a truncated image sum while σz ≤ L and by its
Poisson-summed (Fourier) form when σz > L, which tends to √(2π)·σz/L, i.e.
C → Q/(√(2π)·σy·L·u), far downwind.

Two evaluations share it, each kept to its own floating-point order so that results are
reproducible bit for bit:

* :func:`gaussian_plume_g_m3`, plain and broadcasting: one call evaluates many candidate
  sources (particles) at once. It is the forward model of behaviours that estimate a source;
  with :func:`gaussian_plume_images_g_m3` (its sum over a lid's images) it draws the steady map
  under a recording's report.
* :func:`gaussian_plume_into`, the plume service's in-place kernel (with the mixing lid), which
  writes into preallocated arrays so that millions of points cost no allocation.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from plume_atmosphere.dispersion import DispersionCurves

FloatArray = npt.NDArray[np.float64]

_SQRT_2PI = math.sqrt(2.0 * math.pi)
_SQRT_HALF = math.sqrt(0.5)

# Images farther than |z ± H| + 9σz from a point contribute < exp(−40) of its value.
_IMAGE_SIGMAS = 9.0
# The broadcasting lid sum has at most 256 images a side (σz ≫ L: class A 3 km downwind of a
# 40 m lid is then within 1e-6 of the full sum).
_MAX_IMAGES = 256
# The kernel's Fourier form while σz > L: the n-th term carries exp(−π²n²σz²/2L²) ≤ exp(−4.93 n²).
_FOURIER_TERMS = 4


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


def gaussian_plume_images_g_m3(
    x_down_m: FloatArray,
    y_cross_m: FloatArray,
    z_m: FloatArray,
    release_rate_g_s: float,
    wind_speed_m_s: float,
    release_height_m: float,
    curves: DispersionCurves,
    mixing_height_m: float,
) -> FloatArray:
    """:func:`gaussian_plume_g_m3` under a mixing lid: the sum over the images ±H + 2kL (each
    pair one plain evaluation at z − 2kL); 0 below ground and above the lid."""
    lid = mixing_height_m
    args = (release_rate_g_s, wind_speed_m_s, release_height_m, curves)
    downwind = x_down_m[x_down_m > 0.0]
    sigma_z = float(curves.sigmas(downwind)[1].max()) if downwind.size else 0.0
    images = min(_MAX_IMAGES, math.ceil((2.0 * lid + _IMAGE_SIGMAS * sigma_z) / (2.0 * lid)))
    value = np.zeros(x_down_m.shape)
    for k in range(-images, images + 1):
        value += gaussian_plume_g_m3(x_down_m, y_cross_m, z_m - 2.0 * k * lid, *args)
    return np.where((z_m >= 0.0) & (z_m <= lid), value, 0.0)


def gaussian_plume_into(
    x: FloatArray,
    y: FloatArray,
    z: FloatArray,
    out: FloatArray,
    work: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    release_rate_g_s: float,
    wind_speed_m_s: float,
    release_height_m: float,
    curves: DispersionCurves,
    mixing_height_m: float | None,
) -> None:
    """C (g/m³) at plume-frame points with x > 0 (and 0 ≤ z ≤ L), written into ``out``.

    ``y`` and the four ``work`` arrays (each of ``x``'s length) are overwritten; the caller
    keeps the points outside the plume (x ≤ 0, z < 0, z > L) out of the arrays or zeroes them.
    """
    w0, w1, w2, w3 = work
    sigma_y, sigma_z = curves.sigmas(x, out_y=w1, out_z=w2, ln_x=w0)
    # r = 1/(σ√2), so that exp(−a²/2σ²) = exp(−(a·r)²): multiplications, not divisions.
    r_y = np.divide(_SQRT_HALF, sigma_y, out=sigma_y)
    r_z = np.divide(_SQRT_HALF, sigma_z, out=sigma_z)
    ln_f = y
    ln_f *= r_y
    ln_f *= ln_f
    np.negative(ln_f, out=ln_f)
    if mixing_height_m is None:
        below = np.subtract(z, release_height_m, out=w0)
        image = np.add(z, release_height_m, out=w3)
        value = _gauss_pair(below, image, r_z, ln_f)
    else:
        value = _vertical_with_lid(z, r_z, ln_f, release_height_m, mixing_height_m)
    value *= r_y
    value *= r_z
    # Q/(2π u σy σz) = Q/(π u) · r_y · r_z
    np.multiply(value, release_rate_g_s / (math.pi * wind_speed_m_s), out=out)


def _vertical_with_lid(
    z: FloatArray, r_z: FloatArray, ln_f: FloatArray, height: float, lid: float
) -> FloatArray:
    """f·g with ground and lid reflections; ``r_z`` = 1/(σz√2), ``ln_f`` = −y²/2σy²."""
    value = np.empty_like(z)
    narrow = r_z * lid >= _SQRT_HALF  # σz ≤ L
    if narrow.any():
        value[narrow] = _image_sum(z[narrow], r_z[narrow], ln_f[narrow], height, lid)
    wide = ~narrow
    if wide.any():
        value[wide] = _fourier_sum(z[wide], r_z[wide], ln_f[wide], height, lid)
    return value


def _image_sum(
    z: FloatArray, r_z: FloatArray, ln_f: FloatArray, height: float, lid: float
) -> FloatArray:
    sigma_max = _SQRT_HALF / float(r_z.min())
    reach = 2.0 * lid + _IMAGE_SIGMAS * sigma_max
    images = math.ceil(reach / (2.0 * lid))
    value = np.zeros_like(z)
    for k in range(-images, images + 1):
        shift = 2.0 * k * lid
        value += _gauss_pair(z - height - shift, z + height - shift, r_z, ln_f)
    return value


def _fourier_sum(
    z: FloatArray, r_z: FloatArray, ln_f: FloatArray, height: float, lid: float
) -> FloatArray:
    # Poisson summation of the image sum: Σ_k exp(−(a − 2kL)²/2σ²)
    #   = √(2π)σ/2L · [1 + 2 Σ_n exp(−π²n²σ²/2L²) cos(πna/L)], applied to a = z ∓ H.
    ratio = _SQRT_HALF / (r_z * lid)  # σz / L
    series = np.ones_like(z)
    for n in range(1, _FOURIER_TERMS + 1):
        weight = np.exp(-0.5 * (math.pi * n * ratio) ** 2)
        phase = math.pi * n / lid
        series += weight * 2.0 * np.cos(phase * z) * math.cos(phase * height)
    return np.exp(ln_f) * _SQRT_2PI * ratio * series


def _gauss_pair(a: FloatArray, b: FloatArray, r: FloatArray, ln_f: FloatArray) -> FloatArray:
    """exp(ln f − (a·r)²) + exp(ln f − (b·r)²), computed in place on a and b."""
    for term in (a, b):
        term *= r
        term *= term
        np.subtract(ln_f, term, out=term)
        np.exp(term, out=term)
    a += b
    return a
