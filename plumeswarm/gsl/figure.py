"""The figures of ``plumeswarm bench gsl``: sample trajectories over a plume snapshot, success
rates with their Wilson intervals, and the distribution of final errors."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from plumeswarm.gsl.episode import (
    START_ALTITUDE_M,
    SUCCESS_RADIUS_M,
    Outcome,
    environment_field,
    episode_scenario,
    start_s,
)
from plumeswarm.gsl.registry import CEILING, FLOOR


def _figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    return path


def _plume(fig: Figure, ax: Axes, sample: Outcome) -> None:
    scenario = episode_scenario(sample.spec)
    field, _ = environment_field(scenario)
    src = scenario.plume.sources[0]
    xs = np.linspace(src.x_m - 20.0, src.x_m + 100.0, 241)
    ys = np.linspace(src.y_m - 45.0, src.y_m + 45.0, 181)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, START_ALTITUDE_M)])
    values = field(pts, start_s(scenario)).reshape(gx.shape)
    with np.errstate(divide="ignore"):
        logc = np.log10(values)
    mesh = ax.pcolormesh(xs, ys, np.clip(logc, -5, 1), cmap="Greys", shading="auto")
    fig.colorbar(mesh, ax=ax, label="log10 concentration (g/m³) at 10 m")
    ax.plot(src.x_m, src.y_m, "r*", markersize=14, label="source")


def plot_trajectories(path: Path, samples: Sequence[Outcome]) -> Path:
    """Run 0 of every algorithm (and sensor, named in the legend when there are several) over
    log10 of the field at the flight altitude when run 0 starts (a time-dependent field: its
    snapshot then)."""
    fig = _figure(9, 6)
    ax = fig.add_subplot()
    if samples:
        _plume(fig, ax, samples[0])
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
    env = samples[0].spec.environment if samples else ""
    ax.set_title(f"run 0 of each algorithm, {env} (o start, x estimate / end)")
    ax.legend(loc="upper right", fontsize=8)
    return _save(fig, path)


def _panels(keys: Sequence[tuple[str, str]]) -> tuple[Figure, list[Axes]]:
    n = max(1, len(keys))
    cols = min(n, 4)
    rows = (n + cols - 1) // cols
    fig = _figure(3.6 * cols, 3.2 * rows)
    return fig, [fig.add_subplot(rows, cols, i + 1) for i in range(n)]


def plot_success(path: Path, rows: Sequence[dict[str, Any]]) -> Path:
    """Success (declared within 2 m) of every algorithm with its Wilson 95 % interval, one
    panel per environment and sensor."""
    keys = list(dict.fromkeys((r["environment"], r["sensor"]) for r in rows))
    fig, axes = _panels(keys)
    for ax, (env, sensor) in zip(axes, keys, strict=False):
        cell = [r for r in rows if (r["environment"], r["sensor"]) == (env, sensor)]
        y = np.arange(len(cell))
        rate = np.array([100 * r["success_rate"] for r in cell])
        low = np.array([100 * r["success_ci95"][0] for r in cell])
        high = np.array([100 * r["success_ci95"][1] for r in cell])
        ax.errorbar(rate, y, xerr=[rate - low, high - rate], fmt="o", capsize=3)
        ax.set_yticks(y, [r["algorithm"] for r in cell], fontsize=8)
        ax.set_xlim(-2, 102)
        ax.invert_yaxis()
        ax.set_xlabel("success % (declared ≤ 2 m), 95 % CI")
        ax.set_title(f"{env}, {sensor}", fontsize=9)
    return _save(fig, path)


def plot_errors(path: Path, outcomes: Sequence[Outcome]) -> Path:
    """Final error (the declaration's, or where the vehicles end) of every run, per algorithm,
    one panel per environment and sensor; log scale, the 2 m success radius dashed."""
    keys = list(dict.fromkeys((o.spec.environment, o.spec.sensor) for o in outcomes))
    fig, axes = _panels(keys)
    for ax, key in zip(axes, keys, strict=False):
        cell = [o for o in outcomes if (o.spec.environment, o.spec.sensor) == key]
        algorithms = list(dict.fromkeys(o.spec.algorithm for o in cell))
        data = [
            [max(o.final_error_m, 0.01) for o in cell if o.spec.algorithm == a] for a in algorithms
        ]
        ax.boxplot(data, orientation="horizontal", tick_labels=algorithms, showfliers=True)
        ax.set_xscale("log")
        ax.axvline(SUCCESS_RADIUS_M, color="r", ls="--", lw=1)
        ax.invert_yaxis()
        ax.tick_params(axis="y", labelsize=8)
        ax.set_xlabel("final error m (log)")
        ax.set_title(f"{key[0]}, {key[1]}", fontsize=9)
    return _save(fig, path)


def _scaling_lines(cell: Sequence[dict[str, Any]]) -> dict[tuple[str, str], list[dict[str, Any]]]:
    """The rows of each (algorithm, radio) line: a row no radio changes (radio "–") joins
    every radio line of its algorithm, or is its own line if the algorithm has none."""
    heard: dict[str, list[str]] = {}  # algorithm → the radios that change its cells
    for r in cell:
        radios = heard.setdefault(r["algorithm"], [])
        if r["radio_label"] != "–" and r["radio_label"] not in radios:
            radios.append(r["radio_label"])
    lines: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for r in cell:
        own = [r["radio_label"]] if r["radio_label"] != "–" else heard[r["algorithm"]]
        for radio in own or ["–"]:
            lines.setdefault((r["algorithm"], radio), []).append(r)
    return lines


def plot_scaling(path: Path, rows: Sequence[dict[str, Any]]) -> Path:
    """A swarm grid against its number of vehicles: success (declared within 2 m, Wilson 95 %
    interval) above and the median time to declare below, one column per environment and
    sensor, one line per algorithm and radio (a cell no radio changes joins every radio's
    line); the time panel's dashed and dotted lines are the best 1-vehicle median (the floor and the
    ceiling left out) over N and over √N."""
    keys = list(dict.fromkeys((r["environment"], r["sensor"]) for r in rows))
    cols = max(1, len(keys))
    fig = _figure(4.2 * cols, 7.0)
    colours = colormaps["tab10"]
    for c, (env, sensor) in enumerate(keys):
        top = fig.add_subplot(2, cols, c + 1)
        bottom = fig.add_subplot(2, cols, cols + c + 1)
        cell = [r for r in rows if (r["environment"], r["sensor"]) == (env, sensor)]
        lines = _scaling_lines(cell)
        for k, ((algorithm, radio), points) in enumerate(lines.items()):
            points = sorted(points, key=lambda r: r["vehicles"])
            n = np.array([r["vehicles"] for r in points])
            rate = np.array([100 * r["success_rate"] for r in points])
            low = np.array([100 * r["success_ci95"][0] for r in points])
            high = np.array([100 * r["success_ci95"][1] for r in points])
            label = algorithm if radio in ("–", "perfect") else f"{algorithm}, {radio}"
            style = "-" if radio in ("–", "perfect") else "--"
            colour = colours(k % 10)
            top.errorbar(
                n, rate, yerr=[rate - low, high - rate], fmt="o" + style, color=colour,
                capsize=3, label=label,
            )  # fmt: skip
            timed = [(r["vehicles"], r["median_time_s"]) for r in points if r["median_time_s"]]
            if timed:
                bottom.plot(*zip(*timed, strict=True), "o" + style, color=colour, label=label)
        singles = [
            r["median_time_s"]
            for r in cell
            if r["vehicles"] == 1 and r["median_time_s"] and r["algorithm"] not in (FLOOR, CEILING)
        ]
        best = min(singles, default=None)
        counts = sorted({r["vehicles"] for r in cell})
        if best is not None and counts:
            grid = np.linspace(min(counts), max(counts), 50)
            bottom.plot(grid, best / grid, "k--", lw=0.8, label="best 1-vehicle / N")
            bottom.plot(grid, best / np.sqrt(grid), "k:", lw=0.8, label="best 1-vehicle / √N")
        top.set_ylim(-2, 102)
        top.set_ylabel("declared ≤ 2 m %, 95 % CI")
        top.set_title(f"{env}, {sensor}", fontsize=9)
        bottom.set_xscale("log")
        bottom.set_yscale("log")
        bottom.set_xlabel("vehicles")
        bottom.set_ylabel("median time to declare s")
        for ax in (top, bottom):
            ax.set_xticks(counts, [str(n) for n in counts])
            ax.minorticks_off()
        if c == cols - 1:
            top.legend(fontsize=7, loc="lower right")
            bottom.legend(fontsize=7, loc="upper right")
    return _save(fig, path)
