"""PNG plots a person wants of a plume: plan map, vertical section along the wind, crosswind cuts.

All plots draw on matplotlib ``Figure`` objects with an Agg canvas — no pyplot global state,
no display needed, safe inside a service, a logarithmic colour scale in g/m³
(the field spans many decades near the source), labelled axes in metres, and mark the
source(s). The domain defaults to the box in which the field exceeds ``extent_level_g_m3``
(see :func:`plume_service.mesh.default_bounds`).
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from plume_service.field import ConcentrationField, FloatArray
from plume_service.gaussian import GaussianPlume
from plume_service.mesh import Bounds, default_bounds, gaussian_sources

logger = logging.getLogger(__name__)

#: The seed sensor's detection limit (g/m³): a natural edge for the default domain.
DEFAULT_EXTENT_LEVEL_G_M3 = 0.01
_PIXELS = 300
_DPI = 120
_UNITS = "concentration (g/m³)"


def plot_all(
    field: ConcentrationField,
    out_dir: str | Path,
    *,
    height_m: float | None = None,
    bounds: Bounds | None = None,
    extent_level_g_m3: float = DEFAULT_EXTENT_LEVEL_G_M3,
    t: float | None = None,
) -> list[Path]:
    """Write plan view, along-wind section and crosswind profiles as PNGs into ``out_dir``.

    ``height_m`` is the height of the plan view and profiles; it defaults to the (first)
    source's release height, or ground level for fields without Gaussian sources.
    Returns the paths written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    plumes = gaussian_sources(field)
    if height_m is None:
        height_m = plumes[0].release_height_m if plumes else 0.0
    if bounds is None:
        bounds = _pad_bounds(default_bounds(field, extent_level_g_m3))
    vmax_floor = extent_level_g_m3 / 10.0
    figures = {
        "concentration_plan.png": plan_view(field, bounds, height_m, plumes, vmax_floor, t),
        "concentration_section.png": along_wind_section(field, bounds, plumes, vmax_floor, t),
        "crosswind_profile.png": crosswind_profiles(field, bounds, height_m, plumes, t),
    }
    paths = []
    for name, figure in figures.items():
        path = out / name
        figure.savefig(path, dpi=_DPI)
        paths.append(path)
        logger.info("wrote %s", path)
    return paths


def plan_view(
    field: ConcentrationField,
    bounds: Bounds,
    height_m: float,
    plumes: list[GaussianPlume],
    floor_g_m3: float,
    t: float | None = None,
) -> Figure:
    """Top view: concentration over x (east) and y (north) at ``height_m``."""
    (x0, x1), (y0, y1), _ = bounds
    xs = np.linspace(x0, x1, _PIXELS)
    ys = np.linspace(y0, y1, _PIXELS)
    grid_x, grid_y = np.meshgrid(xs, ys)
    points = np.column_stack([grid_x.ravel(), grid_y.ravel(), np.full(grid_x.size, height_m)])
    values = field.concentration(points, t).reshape(grid_x.shape)
    figure, axes = _figure((8, 5))
    _colour_map(figure, axes, xs, ys, values, floor_g_m3)
    for plume in plumes:
        axes.plot(*plume.source_m, marker="*", color="red", markersize=12, label="source")
        _wind_arrow(axes, plume)
    axes.set(
        xlabel="x east (m)",
        ylabel="y north (m)",
        title=f"Concentration at z = {height_m:g} m (top view)",
        aspect="equal",
    )
    _dedupe_legend(axes)
    return figure


def along_wind_section(
    field: ConcentrationField,
    bounds: Bounds,
    plumes: list[GaussianPlume],
    floor_g_m3: float,
    t: float | None = None,
) -> Figure:
    """Vertical section through the (first) source along the wind: downwind distance × height."""
    _, _, (_, z1) = bounds
    origin, unit = _section_axis(plumes)
    reach = _downwind_reach(bounds, origin, unit)
    distances = np.linspace(0.0, reach, _PIXELS)
    heights = np.linspace(0.0, max(z1, 1.0), _PIXELS)
    grid_s, grid_z = np.meshgrid(distances, heights)
    points = np.column_stack(
        [
            origin[0] + grid_s.ravel() * unit[0],
            origin[1] + grid_s.ravel() * unit[1],
            grid_z.ravel(),
        ]
    )
    values = field.concentration(points, t).reshape(grid_s.shape)
    figure, axes = _figure((8, 4))
    _colour_map(figure, axes, distances, heights, values, floor_g_m3)
    if plumes:
        axes.plot(0.0, plumes[0].release_height_m, marker="*", color="red", markersize=12)
        axes.annotate(
            "source",
            (0.0, plumes[0].release_height_m),
            xytext=(6, 6),
            textcoords="offset points",
            color="red",
        )
    axes.set(
        xlabel="downwind distance from source (m)",
        ylabel="height z (m)",
        title="Vertical section along the wind",
    )
    return figure


def crosswind_profiles(
    field: ConcentrationField,
    bounds: Bounds,
    height_m: float,
    plumes: list[GaussianPlume],
    t: float | None = None,
) -> Figure:
    """Concentration across the wind at ¼, ½ and ¾ of the domain's downwind reach."""
    origin, unit = _section_axis(plumes)
    across = (-unit[1], unit[0])
    reach = _downwind_reach(bounds, origin, unit)
    (x0, x1), (y0, y1), _ = bounds
    half_width = 0.5 * max(x1 - x0, y1 - y0) if not plumes else _half_width(bounds, unit)
    offsets = np.linspace(-half_width, half_width, 600)
    figure, axes = _figure((7, 4))
    for fraction in (0.25, 0.5, 0.75):
        distance = fraction * reach
        points = np.column_stack(
            [
                origin[0] + distance * unit[0] + offsets * across[0],
                origin[1] + distance * unit[1] + offsets * across[1],
                np.full(offsets.size, height_m),
            ]
        )
        axes.plot(offsets, field.concentration(points, t), label=f"{distance:.0f} m downwind")
    axes.axvline(0.0, color="red", linestyle=":", label="source axis")
    axes.set(
        xlabel="crosswind offset from the plume axis (m, + to the left of the wind)",
        ylabel=_UNITS,
        title=f"Crosswind profiles at z = {height_m:g} m",
    )
    axes.legend()
    axes.grid(alpha=0.3)
    return figure


def _figure(size: tuple[float, float]) -> tuple[Figure, Axes]:
    figure = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(figure)
    return figure, figure.subplots()


def _downwind_reach(
    bounds: Bounds, origin: tuple[float, float], unit: tuple[float, float]
) -> float:
    """How far the plume axis runs from the source to the far side of the bounds box."""
    (x0, x1), (y0, y1), _ = bounds
    ends = [
        (x - origin[0]) * unit[0] + (y - origin[1]) * unit[1] for x in (x0, x1) for y in (y0, y1)
    ]
    return max(max(ends), 1.0)


def _colour_map(
    figure: Figure,
    axes: Axes,
    xs: FloatArray,
    ys: FloatArray,
    values: FloatArray,
    floor_g_m3: float,
) -> None:
    positive = values[values > 0]
    top = float(np.percentile(positive, 99.5)) if positive.size else 1.0
    top = max(top, floor_g_m3 * 10)
    shown = np.clip(values, floor_g_m3, top)
    mesh = axes.pcolormesh(
        xs, ys, shown, shading="auto", cmap="viridis", norm=LogNorm(floor_g_m3, top)
    )
    figure.colorbar(mesh, ax=axes, label=_UNITS)


def _section_axis(plumes: list[GaussianPlume]) -> tuple[tuple[float, float], tuple[float, float]]:
    if plumes:
        return plumes[0].source_m, plumes[0].downwind_unit
    return (0.0, 0.0), (1.0, 0.0)


def _wind_arrow(axes: Axes, plume: GaussianPlume) -> None:
    """An arrow in the upper-left corner pointing where the wind blows."""
    ux, uy = plume.downwind_unit
    tail = (0.1 - 0.06 * ux, 0.85 - 0.06 * uy)
    head = (0.1 + 0.06 * ux, 0.85 + 0.06 * uy)
    axes.annotate(
        "",
        xy=head,
        xytext=tail,
        xycoords="axes fraction",
        arrowprops={"arrowstyle": "->", "color": "white", "linewidth": 2},
    )
    axes.text(0.1, 0.72, "wind", transform=axes.transAxes, color="white", ha="center")


def _dedupe_legend(axes: Axes) -> None:
    handles, labels = axes.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    if unique:
        axes.legend(unique.values(), unique.keys(), loc="upper right")


def _half_width(bounds: Bounds, unit: tuple[float, float]) -> float:
    """Half the box's extent across the wind direction ``unit``."""
    (x0, x1), (y0, y1), _ = bounds
    return 0.5 * (abs(unit[1]) * (x1 - x0) + abs(unit[0]) * (y1 - y0))


def _pad_bounds(bounds: Bounds) -> Bounds:
    """Widen a tight level-set box so the plots show some context around it."""
    (x0, x1), (y0, y1), (z0, z1) = bounds
    span = max(x1 - x0, y1 - y0)
    pad = 0.1 * span
    return (x0 - pad, x1 + pad), (y0 - pad, y1 + pad), (0.0, z1 + 0.1 * (z1 - z0))
