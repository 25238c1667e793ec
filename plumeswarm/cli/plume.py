"""``plumeswarm plume sample|mesh|plot|series|intermittency``: look at a scenario's or a
preset's plume field."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import click
import numpy as np
from tqdm import tqdm

from plume_service import GaussianPlume
from plume_service.field import ConcentrationField
from plume_service.filament import FilamentPlume
from plume_service.from_scenario import field_from_scenario
from plume_service.mesh import Bounds, default_bounds, isosurface, write_mesh
from plume_service.puff import PuffPlume
from plume_service.service import source_fields
from plume_service.statistics import HIT_THRESHOLD_G_M3, scenario_statistics


def _field(scenario: str | None, preset: str | None) -> ConcentrationField:
    from plumeswarm.cli.common import fail, scenario_from

    if scenario is not None and preset is not None:
        fail("give --scenario or --preset, not both")
    if preset is not None:
        try:
            return GaussianPlume.preset(preset)
        except ValueError as exc:
            fail(str(exc))
    return field_from_scenario(scenario_from(scenario))


def state_bounds(field: ConcentrationField, t: float) -> Bounds | None:
    """None for a field without filaments or puffs; else the box (m) around its live filaments
    (± their cut-off, 4R by default) and puffs (±3σ) at sim time t, from the ground up.
    ValueError when there are none."""
    dynamic = [f for f in source_fields(field) if isinstance(f, FilamentPlume | PuffPlume)]
    if not dynamic:
        return None
    low, high = [], []
    for source in dynamic:
        if isinstance(source, FilamentPlume):
            centres, radii = source.filaments(t)
            pad = np.repeat(source.params.truncate_radii * radii[:, None], 3, axis=1)
        else:
            centres, sigma_y, sigma_z = source.puffs(t)
            pad = 3.0 * np.column_stack([sigma_y, sigma_y, sigma_z])
        low.append(centres - pad)
        high.append(centres + pad)
    lo, hi = np.concatenate(low), np.concatenate(high)
    if lo.shape[0] == 0:
        raise ValueError(f"no filaments or puffs yet at t = {t:g} s: pick a later --time")
    (x0, y0, _), (x1, y1, z1) = lo.min(axis=0), hi.max(axis=0)
    return ((float(x0), float(x1)), (float(y0), float(y1)), (0.0, max(float(z1), 1.0)))


scenario_option = click.option(
    "--scenario", "-s", default=None, metavar="FILE|NAME", help="Scenario (default: novak2018)."
)
preset_option = click.option(
    "--preset", default=None, metavar="NAME", help="A named plume, e.g. novak2018."
)


FORMAT_OPT = click.option(
    "--format",
    "fmt",
    type=click.Choice(["table", "json"]),
    default="table",
    show_default=True,
    help="table: aligned columns for reading; json: one object for scripts.",
)


@click.group()
def plume() -> None:
    """Sample, mesh and plot the plume field."""


@plume.command(context_settings={"ignore_unknown_options": True})
@scenario_option
@preset_option
@click.argument("coords", nargs=-1, type=float, required=True)
@FORMAT_OPT
@click.option(
    "--time",
    "time_s",
    type=float,
    default=0.0,
    show_default=True,
    help="Sim time (s) for filament and puff plumes.",
)
def sample(
    scenario: str | None, preset: str | None, coords: tuple[float, ...], fmt: str, time_s: float
) -> None:
    """Concentration at points X Y Z [X Y Z ...] (world ENU metres)."""
    from plumeswarm.cli.common import fail

    if not (math.isfinite(time_s) and time_s >= 0.0):
        fail(f"--time must be a number >= 0, got {time_s}")
    if len(coords) % 3 != 0:
        fail(f"expected X Y Z triples, got {len(coords)} numbers")
    if not all(math.isfinite(c) for c in coords):
        fail("coordinates must be finite numbers")
    field = _field(scenario, preset)
    points = [coords[i : i + 3] for i in range(0, len(coords), 3)]
    values = field.concentration(points, time_s)
    if fmt == "json":
        rows = [
            {"x": p[0], "y": p[1], "z": p[2], "concentration_g_m3": float(v)}
            for p, v in zip(points, values, strict=True)
        ]
        click.echo(json.dumps(rows, indent=2))
        return
    click.echo(f"{'x (m)':>10} {'y (m)':>10} {'z (m)':>10} {'C (g/m³)':>14}")
    for p, v in zip(points, values, strict=True):
        click.echo(f"{p[0]:10.3f} {p[1]:10.3f} {p[2]:10.3f} {float(v):14.6g}")


@plume.command()
@scenario_option
@preset_option
@click.option("--level", type=float, required=True, help="Isosurface level (g/m³).")
@click.option("--resolution", type=float, default=0.1, show_default=True, help="Grid step (m).")
@click.option(
    "--out",
    type=click.Path(dir_okay=False, path_type=Path),
    required=True,
    help="Output file, .stl or .obj.",
)
def mesh(
    scenario: str | None, preset: str | None, level: float, resolution: float, out: Path
) -> None:
    """Closed isosurface mesh of the plume at --level, by marching cubes."""
    from plumeswarm.cli.common import fail

    if out.suffix.lower() not in (".stl", ".obj"):
        fail(f"--out must end in .stl or .obj, got {out}")
    if not (math.isfinite(level) and level > 0):
        fail(f"--level must be a positive number, got {level}")
    if not (math.isfinite(resolution) and resolution > 0):
        fail(f"--resolution must be a positive number, got {resolution}")
    field = _field(scenario, preset)
    try:
        bounds = default_bounds(field, level)
        vertices, faces = isosurface(field, level, bounds, resolution, progress=True)
    except ValueError as exc:
        fail(str(exc))
    if len(faces) == 0:
        fail(f"the plume never reaches {level} g/m³: empty mesh, nothing written")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_mesh(out, vertices, faces)
    except OSError as exc:
        fail(f"cannot write {out}: {exc}")
    click.echo(f"wrote {out}: {len(vertices)} vertices, {len(faces)} faces")


@plume.command()
@scenario_option
@preset_option
@click.option(
    "--out",
    type=click.Path(file_okay=False, path_type=Path),
    required=True,
    help="Directory to write the PNGs to (made if missing).",
)
@click.option("--height", type=float, default=None, help="Height of plan view/profiles (m).")
@click.option(
    "--time",
    "time_s",
    type=float,
    default=None,
    help="Sim time (s) of a filament or puff plume (default 60); its box is where they are.",
)
def plot(
    scenario: str | None,
    preset: str | None,
    out: Path,
    height: float | None,
    time_s: float | None,
) -> None:
    """PNGs: plan view, along-wind section, crosswind profiles."""
    from plume_service.plots import plot_all  # matplotlib: imported only when plotting
    from plumeswarm.cli.common import fail

    if time_s is not None and not (math.isfinite(time_s) and time_s >= 0.0):
        fail(f"--time must be a number >= 0, got {time_s}")
    field = _field(scenario, preset)
    try:
        t = 60.0 if time_s is None else time_s
        bounds = state_bounds(field, t)
        dynamic = [f for f in source_fields(field) if isinstance(f, FilamentPlume | PuffPlume)]
        if height is None and dynamic:
            height = dynamic[0].source_m[2]  # the release height, as for a Gaussian plume
        paths = plot_all(
            field, out, height_m=height, bounds=bounds, t=t if bounds is not None else None
        )
    except (OSError, ValueError) as exc:
        fail(str(exc))
    for p in paths:
        click.echo(f"wrote {p}")


#: Most time samples ``plume series`` computes in one call.
MAX_SERIES_SAMPLES = 1_000_000


@plume.command(context_settings={"ignore_unknown_options": True})
@click.argument("scenario_name", metavar="SCENARIO")
@click.option(
    "--point",
    "points",
    type=float,
    nargs=3,
    multiple=True,
    required=True,
    metavar="X Y Z",
    help="A point, world ENU metres (repeat for more).",
)
@click.option("--seconds", type=float, required=True, help="Sim seconds to cover, from t = 0.")
@click.option("--every", type=float, required=True, help="Sim seconds between samples.")
@FORMAT_OPT
def series(
    scenario_name: str,
    points: tuple[tuple[float, float, float], ...],
    seconds: float,
    every: float,
    fmt: str,
) -> None:
    """The field at --point(s) every --every sim seconds over --seconds, without starting any
    process: the same values the plume service would give at those sim times (filaments and
    puffs are time-dependent; a Gaussian plume repeats one value)."""
    from plumeswarm.cli.common import fail, scenario_from

    if not all(math.isfinite(c) for p in points for c in p):
        fail("--point coordinates must be finite numbers")
    if not (math.isfinite(seconds) and seconds >= 0.0):
        fail(f"--seconds must be a number >= 0, got {seconds}")
    if not (math.isfinite(every) and every > 0.0):
        fail(f"--every must be a positive number, got {every}")
    count = math.floor(seconds / every + 1e-9) + 1
    if count > MAX_SERIES_SAMPLES:
        fail(
            f"{count} samples (--seconds / --every) exceed {MAX_SERIES_SAMPLES}; sample less often"
        )
    field = field_from_scenario(scenario_from(scenario_name))
    times = [k * every for k in range(count)]
    rows = []
    for t in tqdm(times, desc="plume series", unit="sample", disable=count < 2000, file=sys.stderr):
        rows.append(field.concentration(list(points), t).tolist())
    if fmt == "json":
        out = {"t": times, "points": [list(p) for p in points], "values_g_m3": rows}
        click.echo(json.dumps(out))
        return
    header = "".join(f"{f'({p[0]:g}, {p[1]:g}, {p[2]:g})':>22}" for p in points)
    click.echo(f"{'t (s)':>10}{header}")
    for t, values in zip(times, rows, strict=True):
        click.echo(f"{t:10.3f}" + "".join(f"{v:22.6g}" for v in values))


SENSOR_NAMES = ("ideal", "novak2018", "mox-tgs2620", "pid", "pid-fast")


def _distance(value: float) -> str:
    return "unbounded" if math.isinf(value) else f"{value:.1f} m"


@plume.command()
@click.argument("scenario_name", metavar="SCENARIO")
@click.option(
    "--sensor",
    "sensor_name",
    type=click.Choice(SENSOR_NAMES),
    default=None,
    help="A sensor preset (default: the scenario's own sensor).",
)
@click.option(
    "--altitude", type=float, default=None, help="Flight altitude (m; default: [env] start box)."
)
@click.option(
    "--at",
    "distances",
    type=float,
    multiple=True,
    metavar="X",
    help="Downwind distance (m) for a crosswind half-width (repeat; default 30, 50, 80).",
)
@click.option("--margin", type=float, default=1.0, show_default=True, help="Mean ≥ margin × floor.")
@FORMAT_OPT
def visibility(
    scenario_name: str,
    sensor_name: str | None,
    altitude: float | None,
    distances: tuple[float, ...],
    margin: float,
    fmt: str,
) -> None:
    """Where a sensor can see the scenario's plume: the region where the time-averaged field
    (the steady Gaussian of the scenario's atmosphere) is at least --margin × the sensor's
    detection floor, at one altitude: how far downwind on the axis, and how wide across."""
    from deploy.visibility import DEFAULT_DISTANCES_M
    from deploy.visibility import visibility as compute
    from plumeswarm.cli.common import fail, scenario_from
    from swarmbus.scenario import Sensor

    scenario = scenario_from(scenario_name)
    sensor = None if sensor_name is None else Sensor(preset=sensor_name)  # type: ignore[arg-type]
    try:
        v = compute(scenario, sensor, altitude, distances or DEFAULT_DISTANCES_M, margin)
    except ValueError as exc:
        fail(str(exc))
    name = sensor_name or "the scenario's"
    if fmt == "json":
        out = {
            "sensor": name,
            "floor_g_m3": v.floor_g_m3,
            "noise_std_g_m3": v.noise_std_g_m3,
            "level_g_m3": v.level_g_m3,
            "altitude_m": v.altitude_m,
            "nearest_m": v.nearest_m,
            "farthest_m": None
            if v.farthest_m is None or math.isinf(v.farthest_m)
            else v.farthest_m,
            "unbounded": v.farthest_m is not None and math.isinf(v.farthest_m),
            "at": [
                {
                    "downwind_m": d,
                    "centreline_g_m3": v.centreline_g_m3[d],
                    "half_width_m": None if math.isinf(w) else w,
                }
                for d, w in v.half_width_m.items()
            ],
        }
        click.echo(json.dumps(out, indent=2))
        return
    click.echo(
        f"sensor {name}: floor {v.floor_g_m3:.4g} g/m³, noise std {v.noise_std_g_m3:.3g} g/m³; "
        f"mean ≥ {v.level_g_m3:.4g} g/m³ at {v.altitude_m:g} m"
    )
    if v.nearest_m is None or v.farthest_m is None:
        click.echo("on the axis: never (the mean stays below the level)")
    else:
        click.echo(
            f"on the axis: from {_distance(v.nearest_m)} to {_distance(v.farthest_m)} downwind"
        )
    click.echo(f"{'downwind (m)':>14} {'mean on axis (g/m³)':>20} {'half-width (m)':>16}")
    for d, w in v.half_width_m.items():
        width = "unbounded" if math.isinf(w) else f"{w:.1f}"
        click.echo(f"{d:14g} {v.centreline_g_m3[d]:20.4g} {width:>16}")


def _fmt(value: float | None, spec: str = ".2f") -> str:
    return "—" if value is None else format(value, spec)


def _intermittency_table(stats: dict[str, Any]) -> None:
    click.echo(
        f"{stats['name']}: threshold {stats['threshold_g_m3']:g} g/m³, "
        f"{stats['seconds']:g} s from t = {stats['start_s']:g} s, a sample every "
        f"{stats['sample_period_s']:g} s"
    )
    click.echo(
        f"{'x (m)':>6}{'y (m)':>7}{'hit frac':>10}{'P(hit 1 s)':>12}"
        f"{'whiff med/p90 (s)':>19}{'blank med/p90 (s)':>19}{'mean (g/m³)':>13}"
    )
    for p in stats["points"]:
        w, b = p["whiff"], p["blank"]
        click.echo(
            f"{p['x_m']:6g}{p['y_m']:7g}{p['hit_fraction']:10.3f}{p['p_hit_1s']:12.3f}"
            f"{_fmt(w['median_s']) + ' / ' + _fmt(w['p90_s']):>19}"
            f"{_fmt(b['median_s']) + ' / ' + _fmt(b['p90_s']):>19}{p['mean_g_m3']:13.3g}"
        )
    for w in stats.get("widths", []):
        click.echo(
            f"  x = {w['x_m']:g} m: time-averaged σy {w['sigma_y_m']:.2f} m "
            f"(Gaussian {w['gaussian_sigma_y_m']:.2f}), σz {w['sigma_z_m']:.2f} m "
            f"(Gaussian {w['gaussian_sigma_z_m']:.2f})"
        )


@plume.command("intermittency")
@click.argument("scenarios", nargs=-1, required=True, metavar="SCENARIO...")
@click.option(
    "--threshold",
    type=float,
    default=HIT_THRESHOLD_G_M3,
    show_default=True,
    help="A hit: a sample at or above this (g/m³; an ideal sensor's level).",
)
@click.option("--seconds", type=float, default=600.0, show_default=True, help="Sim seconds.")
@click.option(
    "--widths",
    "widths_seconds",
    type=float,
    default=0.0,
    metavar="SECONDS",
    help="Also the time-averaged σy, σz over this many sim seconds (0: not).",
)
@click.option("--json", "as_json", is_flag=True, help="One JSON object keyed by world name.")
def intermittency_command(
    scenarios: tuple[str, ...],
    threshold: float,
    seconds: float,
    widths_seconds: float,
    as_json: bool,
) -> None:
    """What a searcher meets at the benchmark's starts: the field sampled every 0.1 s at 30,
    50 and 80 m downwind of the first source, 0–20 m crosswind, at its release height, after
    the plume has settled. Hit fraction, P(≥ 1 hit in 1 s), whiff and blank durations."""
    from plumeswarm.cli.common import fail, scenario_from

    if not (math.isfinite(threshold) and threshold > 0.0):
        fail(f"--threshold must be a positive number, got {threshold}")
    if not (math.isfinite(seconds) and 1.0 <= seconds <= 86_400.0):
        fail(f"--seconds must be between 1 and 86400, got {seconds}")
    if not (math.isfinite(widths_seconds) and 0.0 <= widths_seconds <= 86_400.0):
        fail(f"--widths must be between 0 and 86400, got {widths_seconds}")
    results: dict[str, Any] = {}
    loaded = [scenario_from(name) for name in scenarios]  # every file checked before any work
    for scenario in loaded:
        stats = scenario_statistics(scenario, threshold, seconds, widths_seconds=widths_seconds)
        results[scenario.world.name] = stats
        if not as_json:
            _intermittency_table(stats)
    if as_json:
        click.echo(json.dumps(results, indent=1))
