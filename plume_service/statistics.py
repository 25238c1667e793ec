"""What a searcher meets in a time-dependent plume: the time-averaged width and the
intermittency of the signal at fixed points, measured on any field by sampling it.

Positions are given in the plume frame of a source at ``source_m`` = (x, y, release height)
with the mean wind toward ``downwind`` (a unit (east, north) vector): a point at downwind
distance x, crosswind offset y (to the left of the wind) and height z.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.wind import wind_vector_enu
from plume_service.field import ConcentrationField, FloatArray
from plume_service.from_scenario import field_from_scenario
from swarmbus.scenario import Scenario

#: The default hit threshold: an ideal sensor's level, g/m³ (the behaviours' detection level).
HIT_THRESHOLD_G_M3 = 0.001
#: Sample period (s) of the intermittency statistics: a 10 Hz sensor.
SAMPLE_PERIOD_S = 0.1


def plume_frame_points(
    source_m: tuple[float, float, float],
    downwind: tuple[float, float],
    along_m: FloatArray,
    cross_m: FloatArray,
    height_m: FloatArray,
) -> FloatArray:
    """World ENU points (N, 3) of plume-frame coordinates (broadcast to one shape)."""
    ex, ey = downwind
    a, c, z = np.broadcast_arrays(along_m, cross_m, height_m)
    x = source_m[0] + a * ex - c * ey
    y = source_m[1] + a * ey + c * ex
    return np.column_stack([x.ravel(), y.ravel(), z.ravel()])


@dataclass(frozen=True, slots=True)
class AveragedWidth:
    """Second moments (m) of the time-averaged field at one downwind distance: σy of its
    crosswind profile integrated over height, σz of its vertical profile integrated crosswind
    (about the profile's mean)."""

    x_m: float
    sigma_y_m: float
    sigma_z_m: float


def time_averaged_widths(
    field: ConcentrationField,
    source_m: tuple[float, float, float],
    downwind: tuple[float, float],
    x_m: tuple[float, ...],
    start_s: float,
    seconds: float,
    every_s: float = 0.5,
    half_width_m: float = 30.0,
    top_m: float = 30.0,
    spacing_m: float = 0.5,
) -> list[AveragedWidth]:
    """The field averaged over sim time [start_s, start_s + seconds) (a sample every
    ``every_s``) on a crosswind–vertical plane at each distance, and its second moments."""
    cross = np.arange(-half_width_m, half_width_m + 1e-9, spacing_m)
    height = np.arange(0.0, top_m + 1e-9, spacing_m)
    a, c, z = np.meshgrid(np.asarray(x_m), cross, height, indexing="ij")
    points = plume_frame_points(source_m, downwind, a, c, z)
    total = np.zeros(points.shape[0])
    times = np.arange(start_s, start_s + seconds - 1e-9, every_s)
    for t in times:
        total += field.concentration(points, float(t))
    mean = total.reshape(a.shape) / max(len(times), 1)
    out = []
    for i, x in enumerate(x_m):
        out.append(
            AveragedWidth(
                x, _second_moment(cross, mean[i].sum(1)), _second_moment(height, mean[i].sum(0))
            )
        )
    return out


def _second_moment(axis: FloatArray, weight: FloatArray) -> float:
    mass = float(weight.sum())
    if mass <= 0.0:
        return math.nan
    centre = float((axis * weight).sum()) / mass
    return math.sqrt(float((weight * (axis - centre) ** 2).sum()) / mass)


def _runs(hits: np.ndarray[Any, np.dtype[np.bool_]]) -> tuple[list[int], list[int]]:
    """Lengths (samples) of the complete runs of hits and of non-hits: the runs cut by the
    start or the end of the record are left out."""
    change = np.flatnonzero(np.diff(hits.astype(np.int8))) + 1
    bounds = np.concatenate([[0], change, [hits.size]])
    whiffs: list[int] = []
    blanks: list[int] = []
    for i in range(1, bounds.size - 2):  # drop the first and the last (censored) run
        length = int(bounds[i + 1] - bounds[i])
        (whiffs if hits[bounds[i]] else blanks).append(length)
    return whiffs, blanks


def _summary(lengths: list[int], period_s: float) -> dict[str, float | int | None]:
    if not lengths:
        return {"count": 0, "median_s": None, "p90_s": None, "p99_s": None}
    d = np.asarray(lengths, dtype=np.float64) * period_s
    return {
        "count": len(lengths),
        "median_s": float(np.median(d)),
        "p90_s": float(np.percentile(d, 90)),
        "p99_s": float(np.percentile(d, 99)),
    }


def intermittency(
    field: ConcentrationField,
    source_m: tuple[float, float, float],
    downwind: tuple[float, float],
    x_m: tuple[float, ...],
    cross_m: tuple[float, ...],
    height_m: float,
    start_s: float,
    seconds: float,
    threshold_g_m3: float = HIT_THRESHOLD_G_M3,
    period_s: float = SAMPLE_PERIOD_S,
) -> list[dict[str, Any]]:
    """Per (x, y) point at ``height_m``: the field sampled every ``period_s`` over sim time
    [start_s, start_s + seconds); a hit is a sample ≥ ``threshold_g_m3``. Returns, per point,
    ``hit_fraction``; ``whiff`` and ``blank`` (complete runs of hits / non-hits: count, median,
    90th and 99th percentile duration in s); ``p_hit_1s``, the fraction of consecutive 1 s windows
    with at least one hit; and ``mean_g_m3``."""
    along, cross = np.meshgrid(np.asarray(x_m), np.asarray(cross_m), indexing="ij")
    points = plume_frame_points(source_m, downwind, along, cross, np.asarray(height_m))
    steps = round(seconds / period_s)
    values = np.empty((steps, points.shape[0]))
    for k in range(steps):
        values[k] = field.concentration(points, start_s + k * period_s)
    hits = values >= threshold_g_m3
    per_window = max(1, round(1.0 / period_s))
    windows = steps // per_window
    out = []
    for j, (x, y, _) in enumerate(zip(along.ravel(), cross.ravel(), points[:, 2], strict=True)):
        column = hits[:, j]
        whiffs, blanks = _runs(column)
        framed = column[: windows * per_window].reshape(windows, per_window)
        out.append(
            {
                "x_m": float(x),
                "y_m": float(y),
                "z_m": float(height_m),
                "hit_fraction": float(column.mean()),
                "p_hit_1s": float(framed.any(axis=1).mean()) if windows else math.nan,
                "whiff": _summary(whiffs, period_s),
                "blank": _summary(blanks, period_s),
                "mean_g_m3": float(values[:, j].mean()),
            }
        )
    return out


#: The benchmark's start distances (m downwind) and the crosswind offsets (m) the statistics
#: are published at.
START_DISTANCES_M: tuple[float, ...] = (30.0, 50.0, 80.0)
CROSS_OFFSETS_M: tuple[float, ...] = (0.0, 2.0, 5.0, 10.0, 20.0)
#: A time-dependent field is measured after at least this much release (s), and at least
#: until its gas has travelled 1.5 times the farthest distance.
MIN_WARMUP_S = 60.0


def warmup_s(scenario: Scenario, x_m: tuple[float, ...] = START_DISTANCES_M) -> float:
    """Sim time before the field at ``x_m`` is in its statistically steady state."""
    return max(MIN_WARMUP_S, 1.5 * max(x_m) / scenario.wind.speed_m_s)


def scenario_statistics(
    scenario: Scenario,
    threshold_g_m3: float = HIT_THRESHOLD_G_M3,
    seconds: float = 600.0,
    x_m: tuple[float, ...] = START_DISTANCES_M,
    cross_m: tuple[float, ...] = CROSS_OFFSETS_M,
    height_m: float | None = None,
    widths_seconds: float = 0.0,
) -> dict[str, Any]:
    """The intermittency at ``x_m`` × ``cross_m`` (plume frame of the first source, at
    ``height_m``, default its release height) over ``seconds`` after :func:`warmup_s`; with
    ``widths_seconds`` > 0 also the time-averaged σy, σz (a sample a second over that long)
    next to the steady Gaussian's of the scenario's stability and family."""
    field = field_from_scenario(scenario)
    src = scenario.plume.sources[0]
    source = (src.x_m, src.y_m, src.release_height_m)
    ux, uy, _ = wind_vector_enu(1.0, scenario.wind.from_deg)
    height = src.release_height_m if height_m is None else height_m
    start = warmup_s(scenario, x_m)
    out: dict[str, Any] = {
        "name": scenario.world.name,
        "threshold_g_m3": threshold_g_m3,
        "seconds": seconds,
        "start_s": start,
        "sample_period_s": SAMPLE_PERIOD_S,
        "points": intermittency(
            field, source, (ux, uy), x_m, cross_m, height, start, seconds, threshold_g_m3
        ),
    }
    if widths_seconds > 0.0:
        curves = dispersion_curves(scenario.plume.coefficients, scenario.plume.stability)
        gy, gz = curves.sigmas(np.asarray(x_m, dtype=np.float64))
        measured = time_averaged_widths(
            field, source, (ux, uy), x_m, start, widths_seconds, every_s=1.0
        )
        out["widths"] = [
            {
                "x_m": w.x_m,
                "sigma_y_m": w.sigma_y_m,
                "sigma_z_m": w.sigma_z_m,
                "gaussian_sigma_y_m": float(sy),
                "gaussian_sigma_z_m": float(sz),
            }
            for w, sy, sz in zip(measured, gy, gz, strict=True)
        ]
    return out
