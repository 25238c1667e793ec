"""The figure of ``plumeswarm bench gsl``: sample trajectories over a plume snapshot."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from experiments.gsl_episode import (
    ENVIRONMENTS,
    FIELD_WARMUP_S,
    START_ALTITUDE_M,
    Outcome,
    environment_field,
    episode_scenario,
)
from swarmbus.scenario import load_scenario


def plot_trajectories(path: Path, environment: str, samples: Sequence[Outcome]) -> Path:
    """Run 0 of every algorithm (and sensor, named in the legend when there are several) over
    log10 of the field at the flight altitude when run 0 starts (a time-dependent field: its
    snapshot then)."""
    fig = Figure(figsize=(9, 6))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    if samples:
        scenario = episode_scenario(load_scenario(), samples[0].spec)
        field, _ = environment_field(scenario)
        t = FIELD_WARMUP_S if ENVIRONMENTS[environment].time_dependent else 0.0
        xs, ys = np.linspace(-20.0, 100.0, 241), np.linspace(-45.0, 45.0, 181)
        gx, gy = np.meshgrid(xs, ys)
        pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, START_ALTITUDE_M)])
        values = field(pts, t).reshape(gx.shape)
        with np.errstate(divide="ignore"):
            logc = np.log10(values)
        mesh = ax.pcolormesh(xs, ys, np.clip(logc, -5, 1), cmap="Greys", shading="auto")
        fig.colorbar(mesh, ax=ax, label="log10 concentration (g/m³) at 10 m")
        src = scenario.plume.sources[0]
        ax.plot(src.x_m, src.y_m, "r*", markersize=14, label="source")
    colours = colormaps["tab10"]
    several_sensors = len({outcome.spec.sensor for outcome in samples}) > 1
    for k, outcome in enumerate(samples):
        colour = colours(k % 10)
        name = outcome.spec.algorithm
        if several_sensors:
            name += f" ({outcome.spec.sensor})"
        for i, track in enumerate(outcome.trajectories):
            arr = np.asarray(track)
            label = name if i == 0 else None
            ax.plot(arr[:, 0], arr[:, 1], color=colour, lw=1.0, label=label)
            ax.plot(arr[0, 0], arr[0, 1], "o", color=colour, ms=4)
        ex, ey = outcome.estimate_xy
        ax.plot(ex, ey, "x", color=colour, ms=9, mew=2)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.set_title(f"run 0 of each algorithm, {environment} (o start, x estimate / end)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    return path
