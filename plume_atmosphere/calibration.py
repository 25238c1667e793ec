"""Time-dependent plumes calibrated to the atmosphere: the meander wind and the filaments'
relative dispersion derived from a stability class, so that the time-averaged field has the
steady Gaussian plume's σy and σz.

The crosswind variance of the time-averaged plume at travel time t = x/u splits into the
centreline's meander (the whole plume carried by the large eddies, a wind uniform in space)
and the spread of the instantaneous plume about its centreline (relative dispersion):

    σy²(x) = σm²(t) + σr²(t),         σz²(x) = σr,z²(t)     (the meander is horizontal)

* **Meander.** Each horizontal wind component gets an Ornstein–Uhlenbeck perturbation of std
  σv and Lagrangian timescale T_L (autocorrelation e^(−τ/T_L)). A filament's displacement after
  t is the integral of the wind over its life, whose variance is Taylor's (1921, "Diffusion by
  continuous movements", Proc. London Math. Soc. s2-20:196) result

      σm²(t) = 2 σv² T_L [t − T_L (1 − e^(−t/T_L))]

  T_L comes from Hanna (1982, "Applications in air pollution modeling", in Nieuwstadt & van
  Dop (eds), *Atmospheric Turbulence and Air Pollution Modelling*, Reidel, ch. 7) for the
  neutral surface layer, T_L = 0.5·z/σw with σw = 1.3 u*, u* = κ u / ln(z/z0) (κ = 0.4, z the
  release height, z0 the roughness length; its Coriolis terms, of order f·z/u* ≈ 2·10⁻⁴ at
  10 m, dropped); σv is the least-squares fit (relative, at the
  reference distances) of σm² = share·σy².
* **Relative dispersion.** The rest of the variance, σy² − σm², is the instantaneous plume's:
  the filament's own radius R² = R0² + γ·age plus a random walk of its centre whose variance
  after an age a is S_y(a) = σy²(u a) − σm²(a) − R²(a) horizontally and S_z(a) = σz²(u a) −
  R²(a) vertically — an age-dependent diffusivity K(a) = ½ dS/da, as relative dispersion
  accelerates with the size of the cloud (Richardson's law). Increments are clipped at 0.
* **Local turbulence** (``[wind.turbulence]``, :mod:`plume_atmosphere.wind`): a spatially
  correlated field that moves each filament on its own. Its crosswind and vertical components
  have the stationary stds σv,t and σw,t and the same Lagrangian timescale T_L, so a filament's
  displacement by it has Taylor's variance too, σt²(t) with σv,t (horizontal) and σw,t
  (vertical), and it is counted in the split:

      σy² = σm²(t) + σt,v²(t) + σr²(t),     σz² = σt,w²(t) + σr,z²(t)

  (:func:`derive_turbulence` gives its intensities and length scale).
* **Filaments.** Farrell et al.'s (2002) filaments, published for a 1 m/s wind, scaled to the
  wind speed u at constant turbulence intensity: every diffusivity, the radius growth γ
  included, scales with u (γ = 0.001 m²/s · u/(1 m/s)), and the release rate with u (10
  filaments per metre of wind run), so a filament at a given distance downwind has the size
  and spacing it has in their plume.

The σ curves are the plume's own family and class (``plume_atmosphere.dispersion``), used as in the
Gaussian plume: above 1 m as published, although they are fitted from 100 m (below 100 m they
are extrapolations; docs/plume.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from plume_atmosphere.dispersion import DispersionCurves, dispersion_curves

FloatArray = npt.NDArray[np.float64]

#: von Kármán's constant.
KARMAN = 0.4
#: σw / u* in the neutral surface layer (Hanna 1982).
SIGMA_W_PER_USTAR = 1.3
#: Farrell et al. (2002): radius growth γ (m²/s) and release rate (/s) at their 1 m/s wind.
FARRELL_GROWTH_M2_S = 0.001
FARRELL_RELEASE_RATE_HZ = 10.0
FARRELL_WIND_M_S = 1.0
#: Downwind distances (m) the meander share is fitted at: the benchmark's start distances.
REFERENCE_DISTANCES_M: tuple[float, ...] = (30.0, 50.0, 80.0)
#: Kaimal et al. (1972, "Spectral characteristics of surface-layer turbulence", Q. J. R.
#: Meteorol. Soc. 98:563), neutral surface-layer spectra f·S/u*² = 105f/(1 + 33f)^(5/3) (u) and
#: 17f/(1 + 9.5f)^(5/3) (v), f = n·z/U: their variances σ² = ∫S dn are 105/22 u*² and
#: 17/(19/3) u*², so σu/σv = √(105·19/(22·3·17)) ≈ 1.33; the integral length scale of v,
#: Λ = U·S(0)/(4σv²) = 17z/(4·17·3/19) = 19z/12 ≈ 1.58 z.
KAIMAL_SIGMA_U_PER_V = math.sqrt((105.0 / 22.0) / (17.0 * 3.0 / 19.0))
KAIMAL_LENGTH_PER_HEIGHT = 19.0 / 12.0


def taylor_variance(t_s: FloatArray | float, sigma_v_m_s: float, timescale_s: float) -> FloatArray:
    """Taylor's (1921) displacement variance (m²) after t for an exponential autocorrelation."""
    t = np.asarray(t_s, dtype=np.float64)
    tl = timescale_s
    out: FloatArray = 2.0 * sigma_v_m_s**2 * tl * (t - tl * -np.expm1(-t / tl))
    return out


def lagrangian_timescale_s(wind_speed_m_s: float, height_m: float, roughness_m: float) -> float:
    """Hanna's (1982) neutral surface-layer T_L = 0.5·z/σw, σw = 1.3 κ u / ln(z/z0)."""
    z = max(height_m, 2.0 * roughness_m)
    ustar = KARMAN * wind_speed_m_s / math.log(z / roughness_m)
    return 0.5 * z / (SIGMA_W_PER_USTAR * ustar)


@dataclass(frozen=True, slots=True)
class AtmosphereCalibration:
    """The derived meander (σv, T_L) and the variance budget of the filaments; all pure."""

    curves: DispersionCurves
    wind_speed_m_s: float
    meander_share: float
    sigma_v_m_s: float
    timescale_s: float
    #: The local turbulence's crosswind and vertical stds (m/s; 0: no ``[wind.turbulence]``).
    turbulence_sigma_v_m_s: float = 0.0
    turbulence_sigma_w_m_s: float = 0.0

    @property
    def growth_m2_s(self) -> float:
        """Filament radius growth γ: Farrell's, scaled with the wind speed."""
        return FARRELL_GROWTH_M2_S * self.wind_speed_m_s / FARRELL_WIND_M_S

    @property
    def release_rate_hz(self) -> float:
        """Filaments per second: Farrell's spacing along the wind."""
        return FARRELL_RELEASE_RATE_HZ * self.wind_speed_m_s / FARRELL_WIND_M_S

    def target_sigmas(self, x_m: FloatArray | float) -> tuple[FloatArray, FloatArray]:
        """The steady plume's σy, σz (m) at downwind distances x (m)."""
        x = np.maximum(np.atleast_1d(np.asarray(x_m, dtype=np.float64)), 1e-6)
        return self.curves.sigmas(x)

    def meander_variance(self, t_s: FloatArray | float) -> FloatArray:
        """σm² (m²) of the centreline after a travel time t (Taylor)."""
        return taylor_variance(t_s, self.sigma_v_m_s, self.timescale_s)

    def turbulence_variances(self, t_s: FloatArray | float) -> tuple[FloatArray, FloatArray]:
        """(horizontal, vertical) displacement variances (m²) by the local turbulence after a
        travel time t (Taylor, with T_L)."""
        return (
            taylor_variance(t_s, self.turbulence_sigma_v_m_s, self.timescale_s),
            taylor_variance(t_s, self.turbulence_sigma_w_m_s, self.timescale_s),
        )

    def carried_variance(self, t_s: FloatArray | float) -> FloatArray:
        """The horizontal variance (m²) the wind itself gives a puff or filament centre after a
        travel time t: the meander's plus the local turbulence's."""
        meander = self.meander_variance(t_s)
        if self.turbulence_sigma_v_m_s == 0.0:
            return meander
        out: FloatArray = meander + self.turbulence_variances(t_s)[0]
        return out

    def relative_variances(
        self, age_s: FloatArray, radius2_m2: FloatArray
    ) -> tuple[FloatArray, FloatArray]:
        """(S_y, S_z): the variance a filament centre's random walk must have reached at each
        age (horizontal, vertical), given the filament's R² at that age; made non-decreasing."""
        sigma_y, sigma_z = self.target_sigmas(self.wind_speed_m_s * age_s)
        s_y = sigma_y**2 - self.carried_variance(age_s) - radius2_m2
        s_z = sigma_z**2 - radius2_m2
        if self.turbulence_sigma_w_m_s != 0.0:
            s_z = s_z - self.turbulence_variances(age_s)[1]
        s_y = np.maximum.accumulate(np.maximum(s_y, 0.0))
        s_z = np.maximum.accumulate(np.maximum(s_z, 0.0))
        return s_y, s_z

    def describe(self) -> dict[str, object]:
        x = np.asarray(REFERENCE_DISTANCES_M)
        sy, sz = self.target_sigmas(x)
        sm = np.sqrt(self.meander_variance(x / self.wind_speed_m_s))
        return {
            "family": self.curves.family,
            "stability": self.curves.stability,
            "meander_share": self.meander_share,
            "sigma_v_m_s": self.sigma_v_m_s,
            "timescale_s": self.timescale_s,
            "growth_m2_s": self.growth_m2_s,
            "release_rate_hz": self.release_rate_hz,
            "reference_m": x.tolist(),
            "target_sigma_y_m": sy.tolist(),
            "target_sigma_z_m": sz.tolist(),
            "meander_sigma_m": sm.tolist(),
            "turbulence_sigma_v_m_s": self.turbulence_sigma_v_m_s,
            "turbulence_sigma_w_m_s": self.turbulence_sigma_w_m_s,
        }


def derive_calibration(
    stability: str,
    coefficients: str,
    wind_speed_m_s: float,
    release_height_m: float,
    meander_share: float,
    roughness_m: float = 0.1,
    reference_m: tuple[float, ...] = REFERENCE_DISTANCES_M,
    turbulence_share: float = 0.0,
) -> AtmosphereCalibration:
    """Derive the meander and the relative-dispersion budget (see the module docstring).

    ``meander_share`` in [0, 1): the part of σy² that is centreline meander at the reference
    distances; ``turbulence_share``: the part the local turbulence carries (of σy² and σz²,
    :func:`derive_turbulence`); together below 1. Raises ValueError on a bad class, family or
    number."""
    curves = dispersion_curves(coefficients, stability)
    _check_atmosphere(wind_speed_m_s, roughness_m)
    if not 0.0 <= meander_share < 1.0:
        raise ValueError(f"meander_share must be in [0, 1), got {meander_share!r}")
    if not 0.0 <= turbulence_share < 1.0 - meander_share:
        raise ValueError(
            f"turbulence_share must be in [0, 1 - meander_share = {1.0 - meander_share:g}), "
            f"got {turbulence_share!r}"
        )
    timescale = lagrangian_timescale_s(wind_speed_m_s, release_height_m, roughness_m)
    sigma_v2, _ = class_variances(curves, wind_speed_m_s, timescale, meander_share, reference_m)
    turbulence_v2, turbulence_w2 = class_variances(
        curves, wind_speed_m_s, timescale, turbulence_share, reference_m
    )
    return AtmosphereCalibration(
        curves,
        wind_speed_m_s,
        meander_share,
        math.sqrt(sigma_v2),
        timescale,
        math.sqrt(turbulence_v2),
        math.sqrt(turbulence_w2),
    )


def _check_atmosphere(wind_speed_m_s: float, roughness_m: float) -> None:
    if not wind_speed_m_s > 0.0:
        raise ValueError(f"wind_speed_m_s must be > 0, got {wind_speed_m_s!r}")
    if not roughness_m > 0.0:
        raise ValueError(f"roughness_m must be > 0, got {roughness_m!r}")


def _taylor_fit_variance(
    sigma_m: FloatArray, x_m: FloatArray, wind_speed_m_s: float, timescale_s: float, share: float
) -> float:
    """The σ² whose Taylor variance best fits share·σ(x)² (least squares, relative to the
    target)."""
    shape = taylor_variance(x_m / wind_speed_m_s, 1.0, timescale_s)  # variance per unit σ²
    ratio = shape / sigma_m**2
    return share * float(ratio.sum()) / float((ratio * ratio).sum())


def class_variances(
    curves: DispersionCurves,
    wind_speed_m_s: float,
    timescale_s: float,
    share: float = 1.0,
    reference_m: tuple[float, ...] = REFERENCE_DISTANCES_M,
) -> tuple[float, float]:
    """``share`` of the stability class's σv² and σw² (m²/s²): the variances whose Taylor
    dispersion (Lagrangian timescale T_L) best fits the class's σy(x)² and σz(x)² at the
    reference distances — Pasquill's (1961) reading of his curves, σy ≈ σθ·x near the source,
    carried out to the distances a search flies."""
    x = np.asarray(reference_m, dtype=np.float64)
    sigma_y, sigma_z = curves.sigmas(x)
    return (
        _taylor_fit_variance(sigma_y, x, wind_speed_m_s, timescale_s, share),
        _taylor_fit_variance(sigma_z, x, wind_speed_m_s, timescale_s, share),
    )


@dataclass(frozen=True, slots=True)
class TurbulenceParameters:
    """What ``[wind.turbulence]`` derives: per-component stds (east-north-up for a wind from
    the west: along-wind, crosswind, vertical), the integral length scale and the timescale."""

    std_m_s: tuple[float, float, float]
    length_scale_m: float
    timescale_s: float


def derive_turbulence(
    stability: str,
    coefficients: str,
    wind_speed_m_s: float,
    release_height_m: float,
    share: float,
    roughness_m: float = 0.1,
) -> TurbulenceParameters:
    """The local turbulence of an atmosphere: ``share`` of the class's crosswind and vertical
    variance (:func:`class_variances`): σv,t = √share·σv, σw,t = √share·σw, and along the wind
    σu,t = 1.33·σv,t (Kaimal et al. 1972); the integral length scale 1.58·z (Kaimal's v
    spectrum at the release height z) and the Lagrangian timescale T_L (Hanna 1982). Raises
    ValueError on a bad class, family or number."""
    curves = dispersion_curves(coefficients, stability)
    _check_atmosphere(wind_speed_m_s, roughness_m)
    if not 0.0 <= share < 1.0:
        raise ValueError(f"share must be in [0, 1), got {share!r}")
    timescale = lagrangian_timescale_s(wind_speed_m_s, release_height_m, roughness_m)
    sv2, sw2 = class_variances(curves, wind_speed_m_s, timescale, share)
    sv, sw = math.sqrt(sv2), math.sqrt(sw2)
    z = max(release_height_m, 2.0 * roughness_m)
    return TurbulenceParameters(
        (KAIMAL_SIGMA_U_PER_V * sv, sv, sw), KAIMAL_LENGTH_PER_HEIGHT * z, timescale
    )
