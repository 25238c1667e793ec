"""What ``plumeswarm scenario list`` prints: one line per scenario file."""

from __future__ import annotations

from pathlib import Path

from swarmbus.scenario import (
    GSL_ENVIRONMENTS_DIR,
    GSL_TUNING_DIR,
    SCENARIOS_DIR,
    Scenario,
    ScenarioError,
    load_scenario,
)


def summary(sc: Scenario) -> str:
    return (
        f"{len(sc.vehicles)} vehicle(s), {sc.plume.model} plume, "
        f"{len(sc.plume.sources)} source(s), sensor {sc.sensor.preset or 'custom'}"
    )


def first_comment(path: Path) -> str:
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            return line.lstrip("# ").strip()
        if line.strip():
            break
    return ""


def catalog(directory: Path | None = None) -> list[str]:
    """``name  summary  — first comment line`` for every ``*.toml`` scenario of ``directory``
    (default: the bundled ones, then the benchmark environments as ``gsl/<name>``, then the
    tuning environments as ``gsl/tuning/<name>``); a file that does not validate is listed
    with its error."""
    folder = SCENARIOS_DIR if directory is None else directory
    if not folder.is_dir():
        raise ValueError(f"--dir {folder}: not a directory")
    files = sorted(folder.glob("*.toml"))
    if directory is None:
        files += sorted(GSL_ENVIRONMENTS_DIR.glob("*.toml"))
        files += sorted(GSL_TUNING_DIR.glob("*.toml"))
    if not files:
        raise ValueError(f"--dir {folder}: no scenario files (*.toml)")
    names = [p.relative_to(folder).with_suffix("").as_posix() for p in files]
    width = max(len(name) for name in names)
    lines = []
    for name, p in zip(names, files, strict=True):
        try:
            text = summary(load_scenario(p))
        except ScenarioError as exc:
            text = f"invalid: {exc.field or '<file>'}: {exc.reason}"
        note = first_comment(p)
        lines.append(f"{name:<{width}}  {text}" + (f" — {note}" if note else ""))
    return lines
