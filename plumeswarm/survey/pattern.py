"""The transect pattern of a mass-balance survey: a vertical curtain crosswind of the mean wind,
a distance downwind of the source, crossed by legs at several heights.

The plan is made from what a surveyor knows before flying: where the source is, where the wind
comes from, and a stability class (hence the Pasquill–Gifford σy, σz of the time-averaged
plume at the curtain's distance). The defaults, each a module constant:

* **Distance** ``DEFAULT_DISTANCE_M`` = 50 m downwind (the middle of the benchmark's 30–80 m
  start band, where the calibrated time-dependent environments match the Gaussian's σ).
* **Heights**: the lowest leg at ``LOWEST_LEG_M`` = 2 m (the least clearance a vehicle keeps;
  below it the flux is extrapolated, :mod:`~plumeswarm.survey.flux`), then every
  ``SPACING_SIGMAS`` × σz (at least ``MIN_SPACING_M``) up to the first height at or above the
  release height + ``TOP_SIGMAS`` × σz, where the mean plume has fallen to e^(−4.5) ≈ 1 % of
  its peak.
* **Leg length**: from −``HALF_WIDTH_SIGMAS`` × σy to + that crosswind of the axis (4 σy: the
  time-averaged plume, meander included, holds 99.99 % of its crosswind mass within it).

A vertical spacing of one σz integrates a Gaussian profile by the trapezoid rule to far better
than a per cent (the rule is spectrally accurate on a smooth, decaying integrand); the error of
the survey comes from sampling the instantaneous plume, not from the quadrature.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.plume_formula import downwind_unit
from swarmbus.errors import FieldError
from swarmbus.scenario import Scenario

DEFAULT_DISTANCE_M = 50.0
LOWEST_LEG_M = 2.0
SPACING_SIGMAS = 1.0
MIN_SPACING_M = 1.0
TOP_SIGMAS = 3.0
HALF_WIDTH_SIGMAS = 4.0


class SurveyError(FieldError):
    """A survey that cannot be planned or whose readings give no estimate:
    ``survey: <field>: <reason>``."""

    def __init__(self, field: str, reason: str) -> None:
        super().__init__("survey", field, reason)


@dataclass(frozen=True)
class CurtainPlan:
    """A curtain: the plane ``distance_m`` downwind of ``source_enu_m`` along the wind from
    ``wind_from_deg``, legs at ``heights_m`` from −``half_width_m`` to +``half_width_m``
    crosswind (positive to the left of the wind)."""

    source_enu_m: tuple[float, float]
    wind_from_deg: float
    distance_m: float
    heights_m: tuple[float, ...]
    half_width_m: float

    @property
    def downwind(self) -> tuple[float, float]:
        """The curtain's normal: the ENU unit vector the planned wind blows toward."""
        return downwind_unit(self.wind_from_deg)

    def curtain_frame(self, east_m: float, north_m: float) -> tuple[float, float]:
        """A point's distance downwind of the curtain and its crosswind coordinate on it."""
        ux, uy = self.downwind
        de, dn = east_m - self.source_enu_m[0], north_m - self.source_enu_m[1]
        return de * ux + dn * uy - self.distance_m, dn * ux - de * uy

    def enu(self, downwind_m: float, crosswind_m: float, up_m: float) -> tuple[float, float, float]:
        """The ENU point ``downwind_m`` past the curtain, ``crosswind_m`` along it."""
        ux, uy = self.downwind
        along = self.distance_m + downwind_m
        return (
            self.source_enu_m[0] + along * ux - crosswind_m * uy,
            self.source_enu_m[1] + along * uy + crosswind_m * ux,
            up_m,
        )


def _positive(name: str, value: float) -> float:
    if not math.isfinite(value) or value <= 0.0:
        raise SurveyError(name, f"{value!r} must be a positive number of metres")
    return value


def plan_curtain(
    source_enu_m: tuple[float, float],
    wind_from_deg: float,
    distance_m: float,
    sigma_y_m: float,
    sigma_z_m: float,
    release_height_m: float,
    lowest_m: float = LOWEST_LEG_M,
) -> CurtainPlan:
    """The curtain for a plume of crosswind and vertical spreads ``sigma_y_m``, ``sigma_z_m``
    at ``distance_m`` downwind, released at ``release_height_m`` (module docstring)."""
    _positive("distance_m", distance_m)
    _positive("sigma_y_m", sigma_y_m)
    _positive("sigma_z_m", sigma_z_m)
    _positive("lowest_m", lowest_m)
    if not math.isfinite(release_height_m) or release_height_m < 0.0:
        raise SurveyError("release_height_m", f"{release_height_m!r} must be ≥ 0 m")
    spacing = max(MIN_SPACING_M, SPACING_SIGMAS * sigma_z_m)
    top = max(lowest_m + spacing, release_height_m + TOP_SIGMAS * sigma_z_m)
    count = math.ceil((top - lowest_m) / spacing - 1e-9) + 1
    heights = tuple(float(lowest_m + k * spacing) for k in range(count))
    return CurtainPlan(
        (float(source_enu_m[0]), float(source_enu_m[1])),
        float(wind_from_deg),
        float(distance_m),
        heights,
        HALF_WIDTH_SIGMAS * sigma_y_m,
    )


def scenario_sigmas(scenario: Scenario, distance_m: float) -> tuple[float, float]:
    """σy, σz (m) of the scenario's time-averaged plume (its stability class and coefficient
    family) at ``distance_m`` downwind."""
    plume = scenario.plume
    curves = dispersion_curves(plume.coefficients, plume.stability)
    sigma_y, sigma_z = curves.sigmas(np.array([distance_m], dtype=np.float64))
    return float(sigma_y[0]), float(sigma_z[0])


def plan_for_scenario(scenario: Scenario, distance_m: float = DEFAULT_DISTANCE_M) -> CurtainPlan:
    """The curtain for the scenario's first source, its mean wind direction and its stability
    class: what a surveyor who knows the site, the wind and the weather would plan."""
    if not scenario.plume.sources:
        raise SurveyError("plume.sources", "the scenario has no source to survey")
    source = scenario.plume.sources[0]
    _positive("distance_m", distance_m)
    sigma_y, sigma_z = scenario_sigmas(scenario, distance_m)
    return plan_curtain(
        (source.x_m, source.y_m),
        scenario.wind.from_deg,
        distance_m,
        sigma_y,
        sigma_z,
        source.release_height_m,
    )


def model_coverage(
    plan: CurtainPlan, sigma_y_m: float, sigma_z_m: float, release_height_m: float
) -> float:
    """The share of a steady Gaussian plume's flux (σy, σz at the curtain, ground reflection)
    that crosses the flown rectangle: ±``half_width_m`` crosswind, from the lowest to the top
    leg. The crosswind integral of exp(−y²/2σy²) over ±W is erf(W/√2σy) of its whole; the
    vertical one of the reflected pair over [z₁, zₙ] is half the sum of the two erf
    differences, of its whole ∫₀^∞ = √(2π)·σz."""
    root = math.sqrt(2.0)
    across = math.erf(plan.half_width_m / (root * sigma_y_m))
    low, top = plan.heights_m[0], plan.heights_m[-1]
    vertical = 0.0
    for source in (release_height_m, -release_height_m):
        vertical += math.erf((top - source) / (root * sigma_z_m))
        vertical -= math.erf((low - source) / (root * sigma_z_m))
    return across * 0.5 * vertical
