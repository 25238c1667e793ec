"""Dispersion coefficients σy(x), σz(x) for the Gaussian plume, by family and stability class.

Shared (in swarmbus) by the plume service and by behaviours that carry a plume forward model.

Three families, selected by name through :func:`dispersion_curves`:

``"mcmullen"``
    McMullen (1975) fits of Turner's Pasquill–Gifford curves,
    σ = exp(I + J·ln x + K·(ln x)²) with x in metres, classes A–F.
``"novak2018"``
    The seed thesis's own class-D coefficients (same functional form, K_z = +0.0316).
``"briggs-rural"`` / ``"briggs-urban"``
    Briggs (1973) open-country and urban formulas, classes A–F.

Guard on the McMullen form (documented in docs/plume.md): the fits are quadratic in ln x and
are valid from about 100 m. Where a fit is not monotone increasing in x it is replaced by a
monotone continuation:

* near field: below ``x_near = max(1 m, x*)``, where x* is the fit's minimum (only class A σz has
  one above 1 m, at ≈ 22.2 m), σ grows linearly from the source, σ(x) = σ(x_near)·x/x_near.
  Linear growth is Taylor's short-range limit (σ = σ_v·t with t = x/u). Above 1 m every other
  fit, the novak2018 preset included, is evaluated as published.
* far field: beyond a fit's maximum (K < 0; class F σz peaks at ≈ 435 km, class E at ≈ 1900 km)
  σ is held at that maximum.

All σ are kept within [:data:`SIGMA_MIN_M`, :data:`SIGMA_MAX_M`] so that points a hair downwind
of the source give a large but finite concentration instead of overflowing, and absurdly far
points (novak2018's σz grows without bound) give 0 instead of NaN.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

STABILITY_CLASSES: tuple[str, ...] = ("A", "B", "C", "D", "E", "F")
COEFFICIENT_FAMILIES: tuple[str, ...] = ("mcmullen", "novak2018", "briggs-rural", "briggs-urban")

#: Smallest σ (m) the model uses; reached only within micrometres of the source.
SIGMA_MIN_M = 1e-6
#: Largest σ (m) the model uses (10 000 km); reached only far outside any fit's valid range.
SIGMA_MAX_M = 1e7
_LN_SIGMA_MAX = math.log(SIGMA_MAX_M)

#: Below this downwind distance (m) a McMullen fit is always continued linearly (ln x → −∞).
MCMULLEN_NEAR_CUTOFF_M = 1.0


@dataclass(frozen=True, slots=True)
class LogQuadraticFit:
    """σ(x) = exp(I + J·ln x + K·(ln x)²) with the monotone guards described in the module."""

    i: float
    j: float
    k: float

    @property
    def x_near_m(self) -> float:
        """Below this distance σ is continued linearly towards the source."""
        if self.k > 0.0:
            # Minimum of ln σ over ln x is at ln x* = −J / 2K; the fit decreases below it.
            return max(MCMULLEN_NEAR_CUTOFF_M, math.exp(-self.j / (2.0 * self.k)))
        return MCMULLEN_NEAR_CUTOFF_M

    @property
    def x_far_m(self) -> float:
        """Beyond this distance σ is held constant (the fit's maximum), or inf if none."""
        if self.k < 0.0:
            return math.exp(-self.j / (2.0 * self.k))
        return math.inf

    def raw(self, x_m: float) -> float:
        """The fit exactly as published, without guards (x > 0)."""
        ln_x = math.log(x_m)
        return math.exp(self.i + self.j * ln_x + self.k * ln_x * ln_x)

    def __call__(
        self, x_m: FloatArray, ln_x: FloatArray | None = None, out: FloatArray | None = None
    ) -> FloatArray:
        """σ (m) at downwind distances x > 0 (m); pass ln x if already computed, and ``out``
        to write into a preallocated array."""
        if ln_x is None:
            ln_x = np.log(x_m)
        ln_sigma = np.multiply(ln_x, self.k, out=out)
        ln_sigma += self.j
        ln_sigma *= ln_x
        ln_sigma += self.i
        if self.k > 0.0:  # unbounded growth far away
            np.minimum(ln_sigma, _LN_SIGMA_MAX, out=ln_sigma)
        elif self.k < 0.0 and ln_x.size and ln_x.max() > self._ln_x_far:
            # Past the fit's maximum: hold σ at the maximum.
            np.copyto(ln_sigma, self._ln_sigma_peak, where=ln_x > self._ln_x_far)
        sigma = np.exp(ln_sigma, out=ln_sigma)
        x_near = self.x_near_m
        if x_m.size and x_m.min() < x_near:
            near = x_m < x_near
            slope = self.raw(x_near) / x_near
            sigma[near] = np.maximum(slope * x_m[near], SIGMA_MIN_M)
        return sigma

    @property
    def _ln_x_far(self) -> float:
        return -self.j / (2.0 * self.k)

    @property
    def _ln_sigma_peak(self) -> float:
        ln_x = self._ln_x_far
        return self.i + self.j * ln_x + self.k * ln_x * ln_x

    def describe(self) -> dict[str, object]:
        return {
            "form": "exp(I + J ln x + K (ln x)^2)",
            "I": self.i,
            "J": self.j,
            "K": self.k,
            "x_near_m": self.x_near_m,
            "x_far_m": self.x_far_m if math.isfinite(self.x_far_m) else None,
        }


@dataclass(frozen=True, slots=True)
class BriggsFormula:
    """σ(x) = a·x·(1 + b·x)^p, the shape of every Briggs (1973) formula."""

    a: float
    b: float
    p: float

    def __call__(
        self, x_m: FloatArray, ln_x: FloatArray | None = None, out: FloatArray | None = None
    ) -> FloatArray:
        """σ (m) at downwind distances x > 0 (m); ``ln_x`` is accepted for symmetry, unused."""
        sigma = np.multiply(x_m, self.a, out=out)
        if self.b != 0.0 and self.p != 0.0:
            growth = self.b * x_m
            growth += 1.0
            if self.p == -0.5:
                sigma /= np.sqrt(growth, out=growth)
            elif self.p == 0.5:
                sigma *= np.sqrt(growth, out=growth)
            elif self.p == -1.0:
                sigma /= growth
            else:
                sigma *= growth**self.p
        return np.clip(sigma, SIGMA_MIN_M, SIGMA_MAX_M, out=sigma)

    def describe(self) -> dict[str, object]:
        return {"form": "a x (1 + b x)^p", "a": self.a, "b": self.b, "p": self.p}


SigmaFunction = LogQuadraticFit | BriggsFormula


@dataclass(frozen=True, slots=True)
class DispersionCurves:
    """The pair σy(x), σz(x) of one family and stability class; x is downwind distance in m."""

    family: str
    stability: str
    sigma_y: SigmaFunction
    sigma_z: SigmaFunction

    def sigmas(
        self,
        x_m: FloatArray,
        out_y: FloatArray | None = None,
        out_z: FloatArray | None = None,
        ln_x: FloatArray | None = None,
    ) -> tuple[FloatArray, FloatArray]:
        """σy, σz (m) at downwind distances x > 0 (m), optionally into preallocated arrays.

        ``ln_x`` is a scratch array for ln x (it is overwritten) or None to allocate one.
        """
        if isinstance(self.sigma_y, LogQuadraticFit) or isinstance(self.sigma_z, LogQuadraticFit):
            ln_x = np.log(x_m, out=ln_x)
        else:
            ln_x = None
        return self.sigma_y(x_m, ln_x, out_y), self.sigma_z(x_m, ln_x, out_z)

    @property
    def valid_range_m(self) -> tuple[float, float]:
        """The downwind distances (m) the family's σ is published for."""
        return VALID_RANGE_M[self.family]

    def describe(self) -> dict[str, object]:
        return {
            "family": self.family,
            "stability": self.stability,
            "valid_from_m": self.valid_range_m[0],
            "valid_to_m": self.valid_range_m[1],
            "sigma_y": self.sigma_y.describe(),
            "sigma_z": self.sigma_z.describe(),
        }


def _fit(i: float, j: float, k: float) -> LogQuadraticFit:
    return LogQuadraticFit(i, j, k)


# McMullen, R. W. (1975) "The change of concentration standard deviations with distance",
# J. Air Pollution Control Association 25(10):1057–1058, doi:10.1080/00022470.1975.10470179 —
# fits of Turner (1970) "Workbook of Atmospheric Dispersion Estimates" Pasquill–Gifford curves.
# Class D uses K_z = −0.0316 (the published sign; see the novak2018 family below).
_MCMULLEN: dict[str, tuple[LogQuadraticFit, LogQuadraticFit]] = {
    #      σy: I,      J,      K          σz: I,      J,       K
    "A": (_fit(-1.104, 0.9878, -0.0076), _fit(4.679, -1.7172, 0.2770)),
    "B": (_fit(-1.634, 1.0350, -0.0096), _fit(-1.999, 0.8752, 0.0136)),
    "C": (_fit(-2.054, 1.0231, -0.0076), _fit(-2.341, 0.9477, -0.0020)),
    "D": (_fit(-2.555, 1.0423, -0.0087), _fit(-3.186, 1.1737, -0.0316)),
    "E": (_fit(-2.754, 1.0106, -0.0064), _fit(-3.783, 1.3010, -0.0450)),
    "F": (_fit(-3.143, 1.0148, -0.0070), _fit(-4.490, 1.4024, -0.0540)),
}

# Novák (2018) MSc thesis, the seed simulator's Gazebo plume plugin: McMullen class D with the
# sign of K_z flipped (+0.0316), kept only so the novak2018 preset reproduces the seed.
_NOVAK2018: dict[str, tuple[LogQuadraticFit, LogQuadraticFit]] = {
    "D": (_fit(-2.555, 1.0423, -0.0087), _fit(-3.186, 1.1737, 0.0316)),
}

# Briggs, G. A. (1973) "Diffusion Estimation for Small Emissions", ATDL contribution 79,
# NOAA/ATDL, Oak Ridge, doi:10.2172/5118833 — open-country (rural) formulas, 100 m < x < 10 km,
# as tabulated in Griffiths, R. F. (1994) "Errors in the use of the Briggs parameterization for
# atmospheric dispersion coefficients", Atmospheric Environment 28(17):2861–2865, Table 1.
_BRIGGS_RURAL: dict[str, tuple[BriggsFormula, BriggsFormula]] = {
    "A": (BriggsFormula(0.22, 0.0001, -0.5), BriggsFormula(0.20, 0.0, 0.0)),
    "B": (BriggsFormula(0.16, 0.0001, -0.5), BriggsFormula(0.12, 0.0, 0.0)),
    "C": (BriggsFormula(0.11, 0.0001, -0.5), BriggsFormula(0.08, 0.0002, -0.5)),
    "D": (BriggsFormula(0.08, 0.0001, -0.5), BriggsFormula(0.06, 0.0015, -0.5)),
    "E": (BriggsFormula(0.06, 0.0001, -0.5), BriggsFormula(0.03, 0.0003, -1.0)),
    "F": (BriggsFormula(0.04, 0.0001, -0.5), BriggsFormula(0.016, 0.0003, -1.0)),
}

# Briggs (1973) urban formulas (fitted to the McElroy–Pooler St. Louis data), as tabulated in
# Griffiths (1994), Atmospheric Environment 28(17):2861–2865, Table 1 — the same table EPA
# models use for urban dispersion (A and B share a row, as do E and F).
_BRIGGS_URBAN: dict[str, tuple[BriggsFormula, BriggsFormula]] = {
    "A": (BriggsFormula(0.32, 0.0004, -0.5), BriggsFormula(0.24, 0.001, 0.5)),
    "B": (BriggsFormula(0.32, 0.0004, -0.5), BriggsFormula(0.24, 0.001, 0.5)),
    "C": (BriggsFormula(0.22, 0.0004, -0.5), BriggsFormula(0.20, 0.0, 0.0)),
    "D": (BriggsFormula(0.16, 0.0004, -0.5), BriggsFormula(0.14, 0.0003, -0.5)),
    "E": (BriggsFormula(0.11, 0.0004, -0.5), BriggsFormula(0.08, 0.0015, -0.5)),
    "F": (BriggsFormula(0.11, 0.0004, -0.5), BriggsFormula(0.08, 0.0015, -0.5)),
}

#: Downwind distances (m) each family's σ is published for: Turner's (1970) Pasquill–Gifford
#: curves, which McMullen fitted, span 100 m – 100 km; Briggs (1973) gives 100 m – 10 km.
VALID_RANGE_M: dict[str, tuple[float, float]] = {
    "mcmullen": (100.0, 100_000.0),
    "novak2018": (100.0, 100_000.0),
    "briggs-rural": (100.0, 10_000.0),
    "briggs-urban": (100.0, 10_000.0),
}

_FAMILIES: dict[str, Mapping[str, tuple[SigmaFunction, SigmaFunction]]] = {
    "mcmullen": _MCMULLEN,
    "novak2018": _NOVAK2018,
    "briggs-rural": _BRIGGS_RURAL,
    "briggs-urban": _BRIGGS_URBAN,
}


def dispersion_curves(coefficients: str, stability: str) -> DispersionCurves:
    """Look up σy, σz for a coefficient family and a Pasquill stability class (A–F).

    Raises ValueError naming the bad parameter and its value, and listing the valid ones.
    """
    family = _FAMILIES.get(coefficients) if isinstance(coefficients, str) else None
    if family is None:
        raise ValueError(
            f"coefficients={coefficients!r} is not a known family; "
            f"valid: {', '.join(COEFFICIENT_FAMILIES)}"
        )
    table = family
    if not isinstance(stability, str) or stability not in STABILITY_CLASSES:
        raise ValueError(
            f"stability={stability!r} is not a Pasquill class; "
            f"valid: {', '.join(STABILITY_CLASSES)}"
        )
    if stability not in table:
        raise ValueError(
            f"stability={stability!r} is not defined for coefficients={coefficients!r}; "
            f"valid: {', '.join(sorted(table))}"
        )
    sigma_y, sigma_z = table[stability]
    return DispersionCurves(coefficients, stability, sigma_y, sigma_z)
