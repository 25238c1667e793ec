"""Steady-state Gaussian plume of one continuous point source (Beychok's complete equation).

The equation (ground reflection, and the images of a mixing lid) is written once, in
:mod:`plume_atmosphere.plume_formula`; :class:`GaussianPlume` holds the plume's parameters,
checks them, turns world points into the plume frame and hands them to that module's in-place
kernel, chunk by chunk, in reused work arrays.

Conventions and guards (docs/plume.md):

* World ENU metres in, g/m³ out. ``wind_from_deg`` is meteorological: the direction the wind
  blows *from*, clockwise from north; 270 (the default) blows toward +x (east).
* Upwind of and at the source (x ≤ 0), below ground (z < 0) and above a mixing lid (z > L)
  the concentration is exactly 0 — never NaN or inf, and no floating-point warnings.
* σy, σz come from :mod:`plume_atmosphere.dispersion`, which documents the near-source guard.
"""

from __future__ import annotations

import math
import threading
from typing import Any

import numpy as np

from plume_atmosphere.dispersion import DispersionCurves, dispersion_curves
from plume_atmosphere.plume_formula import downwind_unit, gaussian_plume_into
from plume_service.field import CHUNK_POINTS, ConcentrationField, FloatArray

_SCRATCH = threading.local()

PRESETS: dict[str, dict[str, Any]] = {
    # The seed thesis's plume (Novák 2018): class D, u = 6 m/s, H = 10 m, Q = 10 g/s, source at
    # the world origin, wind toward +x, with its own class-D coefficients (K_z = +0.0316).
    "novak2018": {
        "release_rate": 10.0,
        "wind_speed": 6.0,
        "release_height": 10.0,
        "stability": "D",
        "coefficients": "novak2018",
        "source": (0.0, 0.0),
        "wind_from_deg": 270.0,
        "mixing_height": None,
    },
}


def _finite(
    name: str, value: float, *, minimum: float | None = None, strict: bool = False
) -> float:
    """Validate one scalar parameter; errors name the parameter and its value."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if minimum is not None and (number <= minimum if strict else number < minimum):
        relation = ">" if strict else ">="
        raise ValueError(f"{name} must be {relation} {minimum}, got {value!r}")
    return number


class GaussianPlume(ConcentrationField):
    """Gaussian plume of one continuous point source; see the module docstring for the equation.

    Parameters: ``release_rate`` Q (g/s), ``wind_speed`` u (m/s, > 0), ``release_height`` H (m),
    ``stability`` Pasquill class A–F, ``coefficients`` σ family ("mcmullen", "novak2018",
    "briggs-rural", "briggs-urban"), ``source`` (x, y) world ENU metres, ``wind_from_deg``
    meteorological wind direction, ``mixing_height`` L (m, > H) or None for no lid.
    """

    def __init__(
        self,
        release_rate: float,
        wind_speed: float,
        release_height: float,
        stability: str = "D",
        coefficients: str = "mcmullen",
        source: tuple[float, float] = (0.0, 0.0),
        wind_from_deg: float = 270.0,
        mixing_height: float | None = None,
    ) -> None:
        self.release_rate_g_s = _finite("release_rate", release_rate, minimum=0.0)
        self.wind_speed_m_s = _finite("wind_speed", wind_speed, minimum=0.0, strict=True)
        self.release_height_m = _finite("release_height", release_height, minimum=0.0)
        self.dispersion: DispersionCurves = dispersion_curves(coefficients, stability)
        if len(source) != 2:
            raise ValueError(f"source must be (x, y) in metres, got {source!r}")
        self.source_m = (_finite("source[0]", source[0]), _finite("source[1]", source[1]))
        self.wind_from_deg = _finite("wind_from_deg", wind_from_deg) % 360.0
        self.mixing_height_m: float | None = None
        if mixing_height is not None:
            lid = _finite("mixing_height", mixing_height, minimum=0.0, strict=True)
            if lid <= self.release_height_m:
                raise ValueError(
                    f"mixing_height must be above release_height={self.release_height_m}, "
                    f"got {mixing_height!r}"
                )
            self.mixing_height_m = lid
        # Snap the 1e-16 residues of sin/cos at multiples of 90° so cardinal winds are exact.
        toward_e, toward_n = downwind_unit(self.wind_from_deg)
        self.downwind_unit = (_snap(toward_e), _snap(toward_n))
        self.preset_name: str | None = None

    @classmethod
    def preset(cls, name: str) -> GaussianPlume:
        """A named plume; ``"novak2018"`` is the seed thesis's scenario."""
        if name not in PRESETS:
            raise ValueError(f"unknown plume preset {name!r}; valid: {', '.join(sorted(PRESETS))}")
        plume = cls(**PRESETS[name])
        plume.preset_name = name
        return plume

    @property
    def stability(self) -> str:
        return self.dispersion.stability

    @property
    def coefficients(self) -> str:
        return self.dispersion.family

    def sigmas(self, x_m: FloatArray) -> tuple[FloatArray, FloatArray]:
        """σy, σz (m) at downwind distances x > 0 (m)."""
        return self.dispersion.sigmas(np.asarray(x_m, dtype=np.float64))

    def to_plume_frame(self, points: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """World ENU (n, 3) → plume-frame downwind x, crosswind y (to the left), height z."""
        x, y, z, east, north = (np.empty(points.shape[0]) for _ in range(5))
        self._plume_frame_into(points, x, y, z, east, north)
        return x, y, z

    def _evaluate(self, points: FloatArray, t: float | None, out: FloatArray) -> None:
        n = points.shape[0]
        if self.release_rate_g_s == 0.0 or n == 0:
            out.fill(0.0)
            return
        x, y, z, w0, w1, w2, w3 = _scratch(n)
        # Far-away points may overflow or underflow on the way to an exact 0; that is expected.
        with np.errstate(over="ignore", under="ignore"):
            self._plume_frame_into(points, x, y, z, w0, w1)
            keep = x > 0.0
            keep &= z >= 0.0
            if self.mixing_height_m is not None:
                keep &= z <= self.mixing_height_m
            count = int(np.count_nonzero(keep))
            if count == 0:
                out.fill(0.0)
            elif count <= n // 2:
                # Mostly outside the plume: evaluate only the points inside it.
                values = np.empty(count)
                work = (np.empty(count), np.empty(count), np.empty(count), np.empty(count))
                self._kernel(x[keep], y[keep], z[keep], values, work)
                out.fill(0.0)
                out[keep] = values
            else:
                # Mostly inside: evaluate everything in the scratch arrays, then zero the rest.
                drop = ~keep if count < n else None
                if drop is not None:
                    np.copyto(x, 1.0, where=drop)
                self._kernel(x, y, z, out, (w0, w1, w2, w3))
                if drop is not None:
                    np.copyto(out, 0.0, where=drop)

    def _plume_frame_into(
        self,
        points: FloatArray,
        x: FloatArray,
        y: FloatArray,
        z: FloatArray,
        east: FloatArray,
        north: FloatArray,
    ) -> None:
        """In-place version of :meth:`to_plume_frame` into preallocated arrays."""
        ux, uy = self.downwind_unit
        np.subtract(points[:, 0], self.source_m[0], out=east)
        np.subtract(points[:, 1], self.source_m[1], out=north)
        np.multiply(east, ux, out=x)
        np.multiply(north, uy, out=y)
        x += y
        np.multiply(north, ux, out=y)
        east *= uy
        y -= east
        np.copyto(z, points[:, 2])

    def _kernel(
        self,
        x: FloatArray,
        y: FloatArray,
        z: FloatArray,
        out: FloatArray,
        work: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    ) -> None:
        """C at plume-frame points with x > 0 into ``out``; y and ``work`` are overwritten."""
        gaussian_plume_into(
            x,
            y,
            z,
            out,
            work,
            self.release_rate_g_s,
            self.wind_speed_m_s,
            self.release_height_m,
            self.dispersion,
            self.mixing_height_m,
        )

    def info(self) -> dict[str, Any]:
        return {
            "model": "gaussian_plume",
            "preset": self.preset_name,
            "release_rate_g_s": self.release_rate_g_s,
            "release_height_m": self.release_height_m,
            "source_m": list(self.source_m),
            "stability": self.stability,
            "coefficients": self.coefficients,
            "mixing_height_m": self.mixing_height_m,
            "wind": {
                "speed_m_s": self.wind_speed_m_s,
                "from_deg": self.wind_from_deg,
                "toward_unit_enu": list(self.downwind_unit),
            },
            "dispersion": self.dispersion.describe(),
        }


def _scratch(n: int) -> list[FloatArray]:
    """Seven float64 work arrays of length n, kept per thread and reused chunk after chunk.

    Fresh temporaries of a chunk's size are mmap-ed and page-faulted on every allocation,
    which cost about a third of the evaluation time; reusing buffers avoids that.
    """
    buffers: list[FloatArray] | None = getattr(_SCRATCH, "buffers", None)
    if buffers is None or buffers[0].shape[0] < n:
        size = max(n, CHUNK_POINTS)
        buffers = [np.empty(size, dtype=np.float64) for _ in range(7)]
        _SCRATCH.buffers = buffers
    return [buffer[:n] for buffer in buffers]


def _snap(component: float) -> float:
    return 0.0 if abs(component) < 1e-12 else component
