"""The report's figures (matplotlib, Agg canvas, no pyplot state): one function per PNG."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LogNorm
from matplotlib.figure import Figure

from recorder.flight_log import FlightLog, FloatArray
from recorder.plume_map import PlumeMap

log = logging.getLogger(__name__)

DPI = 110
_COLOURS = [f"C{i}" for i in range(10)]


def _figure(size: tuple[float, float], rows: int = 1) -> tuple[Figure, list[Axes]]:
    figure = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(figure)
    axes = figure.subplots(rows, 1, squeeze=False, sharex=True)
    return figure, [a for row in axes for a in row]


def colour_of(flight: FlightLog, vehicle_id: str) -> str:
    return _COLOURS[flight.vehicles.index(vehicle_id) % len(_COLOURS)]


def save(figure: Figure, path: Path) -> Path:
    figure.savefig(path, dpi=DPI)
    log.info("wrote %s", path)
    return path


def top_view(flight: FlightLog, plume: PlumeMap | None) -> Figure:
    """Trajectories seen from above, over the concentration map at flight altitude if known."""
    figure, (axes,) = _figure((8, 6))
    if plume is not None:
        mesh = axes.pcolormesh(
            plume.xs,
            plume.ys,
            np.ma.masked_less(plume.values, plume.floor_g_m3),
            norm=LogNorm(vmin=plume.floor_g_m3, vmax=max(plume.vmax, plume.floor_g_m3 * 10)),
            cmap="viridis",
            shading="auto",
            alpha=0.85,
        )
        figure.colorbar(mesh, ax=axes, label=f"model concentration at z = {plume.z_m:.1f} m (g/m³)")
        for sx, sy in plume.sources:
            axes.plot(sx, sy, marker="*", color="red", markersize=14, linestyle="", label="source")
        title = "Trajectories over the plume (top view)"
    else:
        sc = None
        for vid, readings in flight.readings.items():
            sc = axes.scatter(
                readings.columns["x_m"],
                readings.columns["y_m"],
                c=readings.columns["reported_g_m3"],
                cmap="viridis",
                s=12,
                zorder=3,
            )
            del vid
        if sc is not None:
            figure.colorbar(sc, ax=axes, label="reported concentration (g/m³)")
        title = "Trajectories, readings coloured (no steady plume map for this recording)"
    for vid, track in flight.tracks.items():
        c = track.columns
        colour = colour_of(flight, vid)
        axes.plot(c["x_m"], c["y_m"], color=colour, linewidth=1.5, label=vid)
        axes.plot(c["x_m"][:1], c["y_m"][:1], marker="o", color=colour, linestyle="")
        axes.plot(c["x_m"][-1:], c["y_m"][-1:], marker="s", color=colour, linestyle="")
    handles, labels = axes.get_legend_handles_labels()
    unique = dict(zip(labels, handles, strict=True))
    axes.legend(unique.values(), unique.keys(), loc="best", fontsize="small")
    axes.set(xlabel="x east (m)", ylabel="y north (m)", title=title, aspect="equal")
    axes.grid(alpha=0.3)
    return figure


def altitude(flight: FlightLog) -> Figure:
    figure, (axes,) = _figure((8, 4))
    for vid, track in flight.tracks.items():
        axes.plot(track.t, track.columns["z_m"], color=colour_of(flight, vid), label=vid)
    axes.set(xlabel="sim time (s)", ylabel="height z (m)", title="Altitude vs time")
    axes.legend(fontsize="small")
    axes.grid(alpha=0.3)
    return figure


def concentration(flight: FlightLog) -> Figure:
    """Reported (solid) and true (dashed) concentration, one panel per vehicle."""
    vehicles = sorted(flight.readings)
    rows = max(len(vehicles), 1)
    figure, axes_list = _figure((8, 1.0 + 2.0 * rows), rows=rows)
    for axes, vid in zip(axes_list, vehicles, strict=False):
        r = flight.readings[vid]
        colour = colour_of(flight, vid)
        axes.plot(r.t, r.columns["reported_g_m3"], color=colour, label="reported")
        axes.plot(r.t, r.columns["true_g_m3"], color="black", linestyle="--", label="true (model)")
        axes.set(ylabel="g/m³", title=vid)
        axes.legend(fontsize="small", loc="upper right")
        axes.grid(alpha=0.3)
    axes_list[-1].set_xlabel("sim time (s)")
    figure.suptitle("Concentration vs time")
    return figure


def reported_vs_model(flight: FlightLog) -> Figure:
    figure, (axes,) = _figure((6, 6))
    high = 0.0
    for vid, r in sorted(flight.readings.items()):
        true, reported = r.columns["true_g_m3"], r.columns["reported_g_m3"]
        ok = np.isfinite(true) & np.isfinite(reported)
        axes.scatter(true[ok], reported[ok], s=10, color=colour_of(flight, vid), label=vid)
        if ok.any():
            high = max(high, float(np.max(true[ok])), float(np.max(reported[ok])))
    line: FloatArray = np.array([0.0, high or 1.0])
    axes.plot(line, line, color="grey", linestyle=":", label="reported = model")
    axes.set(
        xlabel="model (true) concentration (g/m³)",
        ylabel="reported concentration (g/m³)",
        title="Reported vs model",
        aspect="equal",
    )
    axes.legend(fontsize="small")
    axes.grid(alpha=0.3)
    return figure
