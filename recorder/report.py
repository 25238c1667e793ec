"""``plumeswarm report FILE --out DIR``: PNG plots, CSV per vehicle and a one-page report.

Writes into DIR: ``top_view.png``, ``altitude.png``, ``concentration.png``,
``reported_vs_model.png``, ``<vehicle>_track.csv``, ``<vehicle>_readings.csv``, ``report.md``
(links the files) and ``report.html`` (self-contained: images inlined). Columns and formulas are
documented in docs/recording.md.
"""

from __future__ import annotations

import base64
import csv
import html
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from tqdm import tqdm

from recorder import plots
from recorder.flight_log import READING_FIELDS, TRACK_FIELDS, FlightLog, load_flight
from recorder.plume_map import plume_map
from recorder.reader import Recording
from recorder.schema import EventKind
from swarmbus.errors import PlumeswarmError

log = logging.getLogger(__name__)

TRACK_COLUMNS = (*TRACK_FIELDS, "mode")
READING_COLUMNS = (*READING_FIELDS, "error_g_m3")
_INT_COLUMNS = {"tick", "on_ground", "available"}


class ReportError(PlumeswarmError, RuntimeError):
    """A report that cannot be made: one line for the user."""


@dataclass(frozen=True)
class Accuracy:
    vehicle_id: str
    readings: int
    unavailable: int
    mae_g_m3: float
    rmse_g_m3: float
    bias_g_m3: float
    max_abs_error_g_m3: float
    correlation: float

    ROW_HEADER = ("vehicle", "readings", "unavailable", "MAE", "RMSE", "bias", "max abs err", "r")

    def row(self) -> tuple[str, ...]:
        return (
            self.vehicle_id,
            str(self.readings),
            str(self.unavailable),
            *(_fmt(v) for v in (self.mae_g_m3, self.rmse_g_m3, self.bias_g_m3)),
            _fmt(self.max_abs_error_g_m3),
            "—" if math.isnan(self.correlation) else f"{self.correlation:.3f}",
        )


def _fmt(value: float) -> str:
    return "—" if math.isnan(value) else f"{value:.4g}"


def accuracy(vehicle_id: str, reported: np.ndarray, true: np.ndarray) -> Accuracy:
    """Reported vs model over the readings where both are available."""
    ok = np.isfinite(reported) & np.isfinite(true)
    err = reported[ok] - true[ok]
    nan = math.nan
    corr = nan
    if ok.sum() >= 2 and np.std(reported[ok]) > 0 and np.std(true[ok]) > 0:
        corr = float(np.corrcoef(reported[ok], true[ok])[0, 1])
    return Accuracy(
        vehicle_id=vehicle_id,
        readings=int(reported.size),
        unavailable=int(reported.size - ok.sum()),
        mae_g_m3=float(np.mean(np.abs(err))) if err.size else nan,
        rmse_g_m3=float(np.sqrt(np.mean(err**2))) if err.size else nan,
        bias_g_m3=float(np.mean(err)) if err.size else nan,
        max_abs_error_g_m3=float(np.max(np.abs(err))) if err.size else nan,
        correlation=corr,
    )


def accuracy_table(flight: FlightLog) -> list[Accuracy]:
    rows = []
    all_rep, all_true = [], []
    for vid in sorted(flight.readings):
        c = flight.readings[vid].columns
        rows.append(accuracy(vid, c["reported_g_m3"], c["true_g_m3"]))
        all_rep.append(c["reported_g_m3"])
        all_true.append(c["true_g_m3"])
    if len(rows) > 1:
        rows.append(accuracy("all", np.concatenate(all_rep), np.concatenate(all_true)))
    return rows


# ------------------------------------------------------------------------------------ CSV
def _cell(name: str, value: float) -> str:
    if math.isnan(value):
        return ""
    return str(int(value)) if name in _INT_COLUMNS else repr(float(value))


def _mode_at(flight: FlightLog, vid: str, times: np.ndarray) -> list[str]:
    changes = flight.modes.get(vid, [])
    if not changes:
        return [""] * len(times)
    starts = np.array([t for t, _ in changes])
    index = np.searchsorted(starts, times, side="right") - 1
    return [changes[i][1] if i >= 0 else "" for i in index]


def write_csvs(flight: FlightLog, out: Path) -> list[Path]:
    paths = []
    for vid, track in sorted(flight.tracks.items()):
        path = out / f"{vid}_track.csv"
        modes = _mode_at(flight, vid, track.t)
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(TRACK_COLUMNS)
            for i in range(len(track)):
                w.writerow([_cell(n, track.columns[n][i]) for n in TRACK_FIELDS] + [modes[i]])
        paths.append(path)
    for vid, readings in sorted(flight.readings.items()):
        path = out / f"{vid}_readings.csv"
        c = readings.columns
        error = c["reported_g_m3"] - c["true_g_m3"]
        with open(path, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(READING_COLUMNS)
            for i in range(len(readings)):
                row = [_cell(n, c[n][i]) for n in READING_FIELDS]
                w.writerow([*row, _cell("error_g_m3", error[i])])
        paths.append(path)
    return paths


# ------------------------------------------------------------------------------------ page
def _facts(flight: FlightLog, source: Path) -> list[tuple[str, str]]:
    times = [t.t for t in flight.tracks.values() if len(t)] + [
        r.t for r in flight.readings.values() if len(r)
    ]
    span = "—"
    if times:
        t = np.concatenate(times)
        span = f"{t.min():.2f} – {t.max():.2f} s ({t.max() - t.min():.2f} s)"
    behind = sum(1 for e in flight.events if e.kind == EventKind.BEHIND)
    dropped = max((e.dropped for e in flight.events), default=0)
    lost = max((e.lost_upstream for e in flight.events), default=0)
    plume = "—"
    if flight.plume_info is not None:
        i = flight.plume_info
        plume = f"{i.model}, class {i.stability} ({i.coefficients}), u = {i.wind_speed_m_s} m/s"
    elif flight.scenario is not None:
        p = flight.scenario.plume
        plume = f"{p.model}, class {p.stability} ({p.coefficients}) — from the scenario"
    return [
        ("recording", source.name),
        ("world", flight.world),
        ("vehicles", ", ".join(flight.vehicles)),
        ("sim time", span),
        ("messages", str(flight.message_count)),
        ("file", "cut short (recorder killed?)" if flight.truncated else "complete"),
        ("segments", _segments(flight)),
        (
            "recorder",
            f"fell behind {behind}×, dropped {dropped}, {lost} missing from per-tick streams"
            if behind or dropped or lost
            else "kept up, no tick gaps",
        ),
        ("plume", plume),
    ]


def _segments(flight: FlightLog) -> str:
    """The files read and what was not recorded between them (restarted recorders)."""
    text = ", ".join(flight.segments) or "—"
    for g in flight.gaps:
        lost = f"{g.gap_s:.2f} s" if g.gap_s is not None else "an unknown time"
        ticks = (
            f", ticks {g.previous_last_tick} → {g.first_tick} ({g.ticks_missing} missing)"
            if g.ticks_missing is not None
            else ""
        )
        text += f"; not recorded after {g.previous_segment}: {lost}{ticks}"
    return text


FIGURES: dict[str, tuple[str, Callable[[FlightLog], Figure]]] = {
    "altitude.png": ("Altitude vs time", plots.altitude),
    "concentration.png": ("Concentration vs time (reported and true)", plots.concentration),
    "reported_vs_model.png": ("Reported vs model", plots.reported_vs_model),
}


def _markdown(
    facts: list[tuple[str, str]],
    figures: list[tuple[str, str]],
    table: list[Accuracy],
    csvs: list[Path],
) -> str:
    lines = ["# plumeswarm flight report", ""]
    lines += [f"- **{k}**: {v}" for k, v in facts]
    lines += ["", "## Accuracy (reported − model, g/m³)", ""]
    lines.append("| " + " | ".join(Accuracy.ROW_HEADER) + " |")
    lines.append("|" + "---|" * len(Accuracy.ROW_HEADER))
    lines += ["| " + " | ".join(a.row()) + " |" for a in table]
    for name, title in figures:
        lines += ["", f"## {title}", "", f"![{title}]({name})"]
    lines += ["", "## Data", ""] + [f"- [{p.name}]({p.name})" for p in csvs]
    return "\n".join(lines) + "\n"


def _html(
    facts: list[tuple[str, str]],
    figures: list[tuple[str, str]],
    table: list[Accuracy],
    csvs: list[Path],
    out: Path,
) -> str:
    e = html.escape
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'><title>plumeswarm flight report</title>",
        "<style>body{font-family:sans-serif;max-width:60em;margin:auto}"
        "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:2px 8px;"
        "text-align:right}img{max-width:100%}</style></head><body>",
        "<h1>plumeswarm flight report</h1><ul>",
        *(f"<li><b>{e(k)}</b>: {e(v)}</li>" for k, v in facts),
        "</ul><h2>Accuracy (reported − model, g/m³)</h2><table><tr>",
        *(f"<th>{e(h)}</th>" for h in Accuracy.ROW_HEADER),
        "</tr>",
        *("<tr>" + "".join(f"<td>{e(c)}</td>" for c in a.row()) + "</tr>" for a in table),
        "</table>",
    ]
    for name, title in figures:
        data = base64.b64encode((out / name).read_bytes()).decode()
        parts.append(
            f"<h2>{e(title)}</h2><img alt='{e(title)}' src='data:image/png;base64,{data}'>"
        )
    parts.append("<h2>Data</h2><ul>")
    parts += [f"<li><a href='{e(p.name)}'>{e(p.name)}</a></li>" for p in csvs]
    parts.append("</ul></body></html>")
    return "\n".join(parts)


def make_report(path: str | Path, out: Path, progress: bool | None = None) -> list[Path]:
    """Write the report of recording ``path`` into ``out``; returns the files written."""
    recording = Recording.open(path)
    flight = load_flight(recording, progress)
    if not flight.tracks and not flight.readings:
        raise ReportError(f"{path}: no vehicle states or readings in the recording")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ReportError(f"cannot create {out}: {exc.strerror or exc}") from None
    steps: list[tuple[str, str, Callable[[FlightLog], Figure]]] = [
        ("top_view.png", "Trajectories (top view)", lambda f: plots.top_view(f, plume_map(f)))
    ] + [(name, title, draw) for name, (title, draw) in FIGURES.items()]
    written: list[Path] = []
    for name, _, draw in tqdm(
        steps, desc="plots", disable=None if progress is None else not progress, leave=False
    ):
        written.append(plots.save(draw(flight), out / name))
    csvs = write_csvs(flight, out)
    facts = _facts(flight, Path(path))
    table = accuracy_table(flight)
    figures = [(name, title) for name, title, _ in steps]
    (out / "report.md").write_text(_markdown(facts, figures, table, csvs))
    (out / "report.html").write_text(_html(facts, figures, table, csvs, out))
    return [*written, *csvs, out / "report.md", out / "report.html"]
