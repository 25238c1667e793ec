"""The mass-balance estimate of a release rate from a survey's readings, whatever flew them.

The flux of gas through a vertical curtain crosswind of the source, downwind of it, is the
release rate (mass is conserved; Cambaliza et al. 2014, Atmos. Chem. Phys. 14:9029, "Assessment
of uncertainties of an aircraft-based mass balance approach for quantifying urban greenhouse
gas emissions", and the UAS form of Allen et al., Waste Management, "The development and trial
of an unmanned aerial system for the measurement of methane flux from landfill and greenhouse
gas emission hotspots"):

    Q = ∫₀^top ∫ (C(y, z) − C_b) · U⊥ dy dz

Computed here, in this order (docs/survey.md):

1. **Readings on the curtain.** A reading belongs to leg k when it lies within
   ``plane_tolerance_m`` of the curtain's plane, within ``height_tolerance_m`` of the leg's
   height and within the leg's crosswind span; turns and climbs fall outside. A *pass* is a
   run of consecutive readings on one leg; it counts when it spans ≥ 90 % of the leg with at
   least ``MIN_PASS_SAMPLES`` readings.
2. **Background** C_b: given, or the median of the readings in the outer 10 % of each end of
   every pass (where the planned leg is clear of the mean plume).
3. **Per leg**: the trapezoid rule over y of C − C_b along each pass (readings sorted by y),
   plus, for a sensor with a first-order lag τ (``sensor_lag_s``), τ·|v|·(m_end − m_start): a
   lagged reading m obeys τ·dm/dt = C − m, so the response still owed when the pass ends is
   exactly the area the lag moved past it (v the crosswind speed along the pass); the
   passes at one height averaged: a line integral L(z) in g/m², at z the mean height of the
   passes' readings (a vehicle that holds its altitude only to within the tolerance is
   integrated where it flew).
4. **Over height**: the trapezoid rule between the legs' heights; below the lowest leg L is
   held at the lowest leg's value down to the ground (a vehicle cannot fly at z = 0, and a
   plume reflected by the ground has ∂C/∂z = 0 there), and above the top leg it falls
   linearly to 0 one leg spacing higher.
5. **Wind**: U⊥, the mean of the anemometer's readings on the accepted passes, projected on
   the curtain's normal (the planned downwind direction). Q = U⊥ · ∫ L dz.

No estimate is a silent zero: too few heights, no wind, or a curtain on which no reading rises
above the background by ``min_peak_g_m3`` (the curtain misses the plume) raise
:class:`~plumeswarm.survey.pattern.SurveyError`, one line saying which and what to change.
"""

from __future__ import annotations

import math
import statistics
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from agents.behaviors.detection import PLUME_THRESHOLD_G_M3
from plumeswarm.survey.pattern import CurtainPlan, SurveyError

MIN_PASS_SAMPLES = 5
#: A pass must span this share of its leg's length.
MIN_PASS_SPAN = 0.9
#: The outer share of a leg's length, at each end, that gives the background.
EDGE_SHARE = 0.1

__all__ = ["FluxEstimate", "SurveyError", "SurveyReading", "estimate_flux"]


@dataclass(frozen=True)
class SurveyReading:
    """One reading of a surveying vehicle: sim time, ENU position, the concentration it reported
    (g/m³) and the horizontal wind its anemometer measured (ENU, m/s; None: no anemometer)."""

    sim_time_s: float
    position_enu_m: tuple[float, float, float]
    concentration_g_m3: float
    wind_enu_m_s: tuple[float, float] | None


@dataclass(frozen=True)
class FluxEstimate:
    """A survey's estimate. ``line_integrals_g_m2[i]``: L at ``heights_m[i]`` (mean of
    ``passes[i]`` passes); ``flown_fraction``: the share of the estimate between the lowest and
    the top leg (the rest is extrapolated); ``edge_fraction``: the largest mean excess at a
    leg's ends over the peak excess (near 0: the legs reach past the plume)."""

    release_rate_g_s: float
    background_g_m3: float
    wind_normal_m_s: float
    heights_m: tuple[float, ...]
    line_integrals_g_m2: tuple[float, ...]
    passes: tuple[int, ...]
    flown_fraction: float
    edge_fraction: float
    peak_excess_g_m3: float
    readings_used: int


@dataclass
class _Pass:
    leg: int
    t_s: list[float]
    y_m: list[float]
    z_m: list[float]
    c_g_m3: list[float]
    wind: list[tuple[float, float]]


def _passes(
    readings: Sequence[SurveyReading],
    plan: CurtainPlan,
    plane_tolerance_m: float,
    height_tolerance_m: float,
) -> list[_Pass]:
    """The complete passes, in time order."""
    heights = np.asarray(plan.heights_m)
    runs: list[_Pass] = []
    current: _Pass | None = None
    for r in sorted(readings, key=lambda r: r.sim_time_s):
        e, n, z = r.position_enu_m
        dx, y = plan.curtain_frame(e, n)
        leg = int(np.argmin(np.abs(heights - z)))
        on = (
            abs(dx) <= plane_tolerance_m
            and abs(z - heights[leg]) <= height_tolerance_m
            and abs(y) <= plan.half_width_m * (1.0 + 1e-9)
        )
        if not on:
            current = None
            continue
        if current is None or current.leg != leg:
            current = _Pass(leg, [], [], [], [], [])
            runs.append(current)
        current.t_s.append(r.sim_time_s)
        current.y_m.append(y)
        current.z_m.append(z)
        current.c_g_m3.append(r.concentration_g_m3)
        if r.wind_enu_m_s is not None:
            current.wind.append(r.wind_enu_m_s)
    span = MIN_PASS_SPAN * 2.0 * plan.half_width_m
    return [p for p in runs if len(p.y_m) >= MIN_PASS_SAMPLES and max(p.y_m) - min(p.y_m) >= span]


def _edge_values(p: _Pass, half_width_m: float) -> list[float]:
    inner = (1.0 - 2.0 * EDGE_SHARE) * half_width_m
    return [c for y, c in zip(p.y_m, p.c_g_m3, strict=True) if abs(y) >= inner]


def _line_integral(p: _Pass, background: float, lag_s: float) -> float:
    order = np.argsort(p.y_m, kind="stable")
    y = np.asarray(p.y_m)[order]
    c = np.asarray(p.c_g_m3)[order] - background
    area = float(np.trapezoid(c, y))
    if lag_s > 0.0:
        # A first-order sensor reads m with τ·dm/dt = C − m, so ∫ C dy = ∫ m dy + τ·|v|·(m at
        # the pass's end − m at its start): what it still owed when the leg ended.
        speed = (max(p.y_m) - min(p.y_m)) / (p.t_s[-1] - p.t_s[0])
        area += lag_s * speed * (p.c_g_m3[-1] - p.c_g_m3[0])
    return area


def vertical_integral(
    heights_m: Sequence[float], line_g_m2: Sequence[float]
) -> tuple[float, float]:
    """∫ L dz (g/m) over the curtain, and the part of it between the lowest and the top leg:
    L constant from the lowest leg to the ground, the trapezoid rule between legs, a linear fall
    to 0 one spacing above the top leg (module docstring)."""
    z = list(heights_m)
    line = list(line_g_m2)
    flown = sum(0.5 * (line[i] + line[i + 1]) * (z[i + 1] - z[i]) for i in range(len(z) - 1))
    below = line[0] * z[0]
    above = 0.5 * line[-1] * (z[-1] - z[-2])
    return below + flown + above, flown


def _legs_text(plan: CurtainPlan) -> str:
    heights = ", ".join(f"{h:.1f}" for h in plan.heights_m)
    return (
        f"legs at z = {heights} m, y within ±{plan.half_width_m:.1f} m, "
        f"{plan.distance_m:.1f} m downwind"
    )


def estimate_flux(
    readings: Sequence[SurveyReading],
    plan: CurtainPlan,
    background_g_m3: float | None = None,
    plane_tolerance_m: float = 5.0,
    height_tolerance_m: float = 0.5,
    min_peak_g_m3: float = PLUME_THRESHOLD_G_M3,
    sensor_lag_s: float = 0.0,
) -> FluxEstimate:
    """The release rate (g/s) from ``readings`` on ``plan``'s curtain (module docstring);
    ``sensor_lag_s``: the time constant of a linear first-order sensor, whose lag is undone."""
    if not (math.isfinite(sensor_lag_s) and sensor_lag_s >= 0.0):
        raise SurveyError("sensor_lag_s", f"{sensor_lag_s!r} must be ≥ 0 s")
    passes = _passes(readings, plan, plane_tolerance_m, height_tolerance_m)
    flown_legs = sorted({p.leg for p in passes})
    if len(flown_legs) < 2:
        raise SurveyError(
            "legs",
            f"{len(flown_legs)} height(s) with a complete pass ({len(readings)} readings; "
            f"{_legs_text(plan)}): the mass balance needs complete passes at 2 heights or more",
        )
    if background_g_m3 is None:
        edges = [c for p in passes for c in _edge_values(p, plan.half_width_m)]
        background = statistics.median(edges) if edges else 0.0
    else:
        background = float(background_g_m3)
    used = [c for p in passes for c in p.c_g_m3]
    peak = max(used) - background
    if not peak >= min_peak_g_m3:
        raise SurveyError(
            "curtain",
            f"no reading rises above the background ({background:.3g} g/m³) by "
            f"{min_peak_g_m3:g} g/m³ or more ({len(used)} readings on the curtain; "
            f"{_legs_text(plan)}): the curtain misses the plume, or the plume is too dilute "
            "there; move the curtain onto the plume, closer to the source or widen it",
        )
    winds = [w for p in passes for w in p.wind]
    if not winds:
        raise SurveyError("wind", "no reading on the curtain carries an anemometer reading")
    ux, uy = plan.downwind
    mean_e = math.fsum(w[0] for w in winds) / len(winds)
    mean_n = math.fsum(w[1] for w in winds) / len(winds)
    normal = mean_e * ux + mean_n * uy
    if not normal > 0.0:
        raise SurveyError(
            "wind",
            f"the mean measured wind ({mean_e:.2f}, {mean_n:.2f}) m/s ENU does not blow "
            f"through the curtain (U⊥ = {normal:.2f} m/s): plan it downwind of the source",
        )
    heights, lines, counts, edge = [], [], [], 0.0
    for leg in flown_legs:
        mine = [p for p in passes if p.leg == leg]
        heights.append(statistics.fmean(z for p in mine for z in p.z_m))
        lines.append(statistics.fmean(_line_integral(p, background, sensor_lag_s) for p in mine))
        counts.append(len(mine))
        ends = [c - background for p in mine for c in _edge_values(p, plan.half_width_m)]
        if ends:
            edge = max(edge, statistics.fmean(ends) / peak)
    total, flown = vertical_integral(heights, lines)
    if not total > 0.0:
        raise SurveyError(
            "curtain",
            f"the excess over the background integrates to {total:.3g} g/m ≤ 0 "
            f"({_legs_text(plan)}): the background is wrong or the curtain misses the plume",
        )
    return FluxEstimate(
        release_rate_g_s=normal * total,
        background_g_m3=background,
        wind_normal_m_s=normal,
        heights_m=tuple(heights),
        line_integrals_g_m2=tuple(lines),
        passes=tuple(counts),
        flown_fraction=flown / total,
        edge_fraction=edge,
        peak_excess_g_m3=peak,
        readings_used=len(used),
    )
