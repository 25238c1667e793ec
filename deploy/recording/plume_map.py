"""The concentration map under a report's top view, from the plume the flight was recorded in.

The plume's parameters come from the ``plume/info`` reply the recorder asked for, else from the
scenario stored in the recording; the field itself is computed by ``plume_service`` (deploy may
import process packages). Without either, the report draws no map.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from deploy.recording.flight import Flight, FloatArray

if TYPE_CHECKING:
    from plume_service import ConcentrationField

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


def plume_field(flight: Flight) -> ConcentrationField | None:
    try:
        from plume_service import GaussianPlume, PlumeField
        from plume_service.from_scenario import field_from_scenario
    except ImportError as exc:  # a deployment without the plume package
        log.warning("no plume model available (%s): the map is left out", exc)
        return None
    try:
        info = flight.plume_info
        if info is not None and info.model == "gaussian":
            plumes = [
                GaussianPlume(
                    release_rate=s.release_rate_g_s,
                    wind_speed=info.wind_speed_m_s,
                    release_height=s.release_height_m,
                    stability=info.stability,
                    coefficients=info.coefficients,
                    source=(s.x_m, s.y_m),
                    wind_from_deg=info.wind_from_deg,
                    mixing_height=info.mixing_height_m,
                )
                for s in info.sources
            ]
            return plumes[0] if len(plumes) == 1 else PlumeField(plumes)
        if flight.scenario is not None:
            return field_from_scenario(flight.scenario)
    except ValueError as exc:
        log.warning("the recorded plume parameters are not usable (%s): no map", exc)
    return None


def _sources(flight: Flight) -> list[tuple[float, float]]:
    if flight.plume_info is not None:
        return [(s.x_m, s.y_m) for s in flight.plume_info.sources]
    if flight.scenario is not None:
        return [(s.x_m, s.y_m) for s in flight.scenario.plume.sources]
    return []


def flight_altitude_m(flight: Flight) -> float:
    """Median height of the airborne samples (the height the map is drawn at)."""
    heights = [t.columns["z_m"][t.columns["on_ground"] < 0.5] for t in flight.tracks.values()]
    airborne = np.concatenate(heights) if heights else np.empty(0)
    return float(np.median(airborne)) if airborne.size else 0.0


def plume_map(flight: Flight) -> PlumeMap | None:
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
