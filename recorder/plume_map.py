"""The concentration map under a report's top view, from the plume the flight was recorded in.

The plume's parameters come from the ``plume/info`` reply the recorder asked for, else from the
scenario stored in the recording; the field is the steady Gaussian plume of
:mod:`plume_atmosphere.plume_formula` (ground reflection, and the images of a mixing lid when there
is one), the equation the plume service serves. A time-dependent plume (filaments, puffs) has no
steady map, and without parameters there is none either: the report then colours the readings.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from plume_atmosphere.dispersion import DispersionCurves, dispersion_curves
from plume_atmosphere.plume_formula import (
    gaussian_plume_g_m3,
    gaussian_plume_images_g_m3,
    plume_frame,
)
from recorder.flight_log import FlightLog, FloatArray

log = logging.getLogger(__name__)

FLOOR_G_M3 = 1e-3
PIXELS = 220


@dataclass(frozen=True)
class PlumeMap:
    xs: FloatArray
    ys: FloatArray
    values: FloatArray  # (len(ys), len(xs)) g/m³
    z_m: float
    sources: list[tuple[float, float]]
    floor_g_m3: float = FLOOR_G_M3

    @property
    def vmax(self) -> float:
        return float(np.nanmax(self.values)) if self.values.size else 0.0


@dataclass(frozen=True)
class SteadyPlume:
    """The parameters of a steady Gaussian plume: one wind, one σ family, its sources as
    (x m, y m, release rate g/s, release height m)."""

    curves: DispersionCurves
    wind_speed_m_s: float
    wind_from_deg: float
    mixing_height_m: float | None
    sources: list[tuple[float, float, float, float]]

    def concentration(self, points: FloatArray) -> FloatArray:
        """C (g/m³) at world ENU points (n, 3): the sum over sources of the Gaussian plume."""
        total = np.zeros(points.shape[0])
        for sx, sy, rate, height in self.sources:
            x, y = plume_frame(points[:, 0], points[:, 1], sx, sy, self.wind_from_deg)
            total += self._source(x, y, points[:, 2], rate, height)
        return total

    def _source(
        self, x: FloatArray, y: FloatArray, z: FloatArray, rate: float, height: float
    ) -> FloatArray:
        args = (rate, self.wind_speed_m_s, height, self.curves)
        if self.mixing_height_m is None:
            return gaussian_plume_g_m3(x, y, z, *args)
        return gaussian_plume_images_g_m3(x, y, z, *args, self.mixing_height_m)


def plume_field(flight: FlightLog) -> SteadyPlume | None:
    """The steady plume of the recording, or None (time-dependent, unknown, or not usable)."""
    info, scenario = flight.plume_info, flight.scenario
    try:
        if info is not None and info.model == "gaussian":
            return SteadyPlume(
                dispersion_curves(info.coefficients, info.stability),
                info.wind_speed_m_s,
                info.wind_from_deg,
                info.mixing_height_m,
                [(s.x_m, s.y_m, s.release_rate_g_s, s.release_height_m) for s in info.sources],
            )
        if info is None and scenario is not None:
            plume = scenario.plume
            if {src.model or plume.model for src in plume.sources} != {"gaussian"}:
                return None
            return SteadyPlume(
                dispersion_curves(plume.coefficients, plume.stability),
                scenario.wind.speed_m_s,
                scenario.wind.from_deg,
                plume.mixing_height_m,
                [(s.x_m, s.y_m, s.release_rate_g_s, s.release_height_m) for s in plume.sources],
            )
    except ValueError as exc:
        log.warning("the recorded plume parameters are not usable (%s): no map", exc)
    return None


def _sources(flight: FlightLog) -> list[tuple[float, float]]:
    if flight.plume_info is not None:
        return [(s.x_m, s.y_m) for s in flight.plume_info.sources]
    if flight.scenario is not None:
        return [(s.x_m, s.y_m) for s in flight.scenario.plume.sources]
    return []


def flight_altitude_m(flight: FlightLog) -> float:
    """Median height of the airborne samples (the height the map is drawn at)."""
    heights = [t.columns["z_m"][t.columns["on_ground"] < 0.5] for t in flight.tracks.values()]
    airborne = np.concatenate(heights) if heights else np.empty(0)
    return float(np.median(airborne)) if airborne.size else 0.0


def plume_map(flight: FlightLog) -> PlumeMap | None:
    """The map over the area the vehicles flew (and the sources), or None without a model."""
    field = plume_field(flight)
    if field is None:
        return None
    sources = _sources(flight)
    xs_all = [t.columns["x_m"] for t in flight.tracks.values()] + [
        np.array([s[0] for s in sources])
    ]
    ys_all = [t.columns["y_m"] for t in flight.tracks.values()] + [
        np.array([s[1] for s in sources])
    ]
    x = np.concatenate(xs_all)
    y = np.concatenate(ys_all)
    if x.size == 0:
        return None
    margin = max(5.0, 0.15 * max(np.ptp(x), np.ptp(y)))
    xs = np.linspace(x.min() - margin, x.max() + margin, PIXELS)
    ys = np.linspace(y.min() - margin, y.max() + margin, PIXELS)
    gx, gy = np.meshgrid(xs, ys)
    z_m = flight_altitude_m(flight)
    points = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z_m)])
    values = np.asarray(field.concentration(points), dtype=np.float64).reshape(gx.shape)
    return PlumeMap(xs=xs, ys=ys, values=values, z_m=z_m, sources=sources)
