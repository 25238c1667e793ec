"""The two plots docs/plume.md shows of the filament model: ``python -m
plume_service.dynamic_plots OUT_DIR`` writes

* ``filament_series.png``: the concentration at 20 m downwind on the axis of the bundled
  ``filament`` scenario (meandering wind) over 60 s at 20 Hz — bursts and silences;
* ``filament_average.png``: the time-averaged filament field across the wind at 5 m downwind
  (steady 1 m/s wind, no meander) against the closed form
  ``Q/(2πu s²)·exp(−y²/2s²)·[exp(−(z−H)²/2s²) + exp(−(z+H)²/2s²)]``,
  ``s² = R0² + (2K + γ)x/u``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from plume_atmosphere.wind import wind_model
from plume_service.filament import FilamentPlume
from plume_service.from_scenario import field_from_scenario
from swarmbus.scenario import PlumeFilament, Wind, load_scenario, resolve_scenario_path


def series_plot(path: Path) -> Path:
    field = field_from_scenario(load_scenario(resolve_scenario_path("filament")))
    times = np.arange(20.0, 80.0, 0.05)
    values = [field.concentration([(20.0, 0.0, 5.0)], t)[0] for t in times]
    fig = Figure(figsize=(8, 3), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot(times, values, lw=0.8)
    ax.set(
        xlabel="sim time (s)",
        ylabel="concentration (g/m³)",
        title="filament scenario: (20, 0, 5) m, meandering wind, sampled at 20 Hz",
    )
    fig.tight_layout()
    fig.savefig(path)
    return path


def average_plot(path: Path, seconds: float = 300.0) -> Path:
    params = PlumeFilament(release_rate_hz=200.0, max_age_s=10.0)
    q, u, h, x = 1.0, 1.0, 0.5, 5.0
    plume = FilamentPlume((0.0, 0.0, h), q, params, wind_model(Wind(speed_m_s=u), 0), seed=0)
    offsets = np.linspace(-1.5, 1.5, 61)
    points = np.column_stack([np.full(61, x), offsets, np.full(61, h)])
    times = np.arange(12.0, 12.0 + seconds, 0.05)
    mean = np.mean([plume.concentration(points, t) for t in times], axis=0)
    s2 = (
        params.initial_radius_m**2
        + (2 * params.centerline_diffusivity_m2_s + params.growth_m2_s) * x / u
    )
    image = 1.0 + math.exp(-((2 * h) ** 2) / (2 * s2))
    analytic = q / (2 * math.pi * u * s2) * np.exp(-(offsets**2) / (2 * s2)) * image
    fig = Figure(figsize=(6, 4), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.plot(offsets, mean, ".", label=f"filaments, {seconds:.0f} s average")
    ax.plot(offsets, analytic, "-", label="closed form")
    ax.set(
        xlabel="crosswind offset (m)",
        ylabel="mean concentration (g/m³)",
        title=f"{x:g} m downwind, u = {u:g} m/s, no meander, Q = {q:g} g/s, H = {h:g} m",
    )
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    return path


def main(argv: list[str]) -> int:
    out = Path(argv[0]) if argv else Path("docs")
    out.mkdir(parents=True, exist_ok=True)
    for written in (
        series_plot(out / "filament_series.png"),
        average_plot(out / "filament_average.png"),
    ):
        sys.stdout.write(f"wrote {written}\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
