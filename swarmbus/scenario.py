"""Scenario files: TOML validated into typed, immutable config objects (their schema:
:mod:`swarmbus.scenario_spec`, whose names are all importable from here too).

A randomised environment family's ``[randomise]`` table (:data:`FAMILY_TABLE`) is not part of
the scenario: it is set aside when the file is read (the rest is the family's base scenario) and
read by ``plumeswarm.gsl.family``.

A bad file gives one line naming the file, the field and what is wrong
(:class:`ScenarioError`), never a traceback.
"""

from __future__ import annotations

import hashlib
import logging
import re
import tomllib
from collections.abc import Iterable, Iterator
from pathlib import Path

import msgspec

from plume_atmosphere.calibration import (
    AtmosphereCalibration,
    derive_calibration,
    derive_turbulence,
)
from plume_atmosphere.gases import FORMULAS
from swarmbus.errors import FieldError
from swarmbus.keys import serves_several
from swarmbus.radio import RadioSpec
from swarmbus.scenario_errors import did_you_mean, explain
from swarmbus.scenario_spec import (
    DEFAULT_SCENARIO,
    FAMILY_TABLE,
    GSL_ENVIRONMENTS_DIR,
    GSL_TUNING_DIR,
    MAVLINK_MAX_SYSID,
    MAX_VEHICLES,
    RENAMED_KEYS,
    SCENARIOS_DIR,
    SENSOR_PRESETS,
    AnemometerSpec,
    Env,
    Failsafe,
    GatewaySpec,
    Mox,
    Origin,
    Plume,
    PlumeCalibration,
    PlumeFilament,
    PlumeModel,
    PlumePuff,
    Scenario,
    Sensor,
    SensorPreset,
    Source,
    Time,
    VehicleSpec,
    Wind,
    WindField,
    WindMeander,
    WindTurbulence,
    WorldSpec,
    not_on_mavlink_note,
    sysid_at,
)
from swarmbus.session import NetworkConfig
from swarmbus.vehicle_types import VehicleTypeError, load_vehicle_type

__all__ = [
    "DEFAULT_SCENARIO",
    "FAMILY_TABLE",
    "GSL_ENVIRONMENTS_DIR",
    "GSL_TUNING_DIR",
    "MAVLINK_MAX_SYSID",
    "MAX_VEHICLES",
    "RENAMED_KEYS",
    "SCENARIOS_DIR",
    "SENSOR_PRESETS",
    "AnemometerSpec",
    "Env",
    "Failsafe",
    "GatewaySpec",
    "Mox",
    "Origin",
    "Plume",
    "PlumeCalibration",
    "PlumeFilament",
    "PlumeModel",
    "PlumePuff",
    "RadioSpec",
    "Scenario",
    "ScenarioError",
    "Sensor",
    "SensorPreset",
    "Source",
    "Time",
    "VehicleSpec",
    "Wind",
    "WindField",
    "WindMeander",
    "WindTurbulence",
    "WorldSpec",
    "apply_overrides",
    "bundled_scenarios",
    "calibrate_scenario",
    "load_scenario",
    "not_on_mavlink_note",
    "parse_override_value",
    "parse_scenario",
    "read_renamed_keys",
    "renamed_override",
    "resolve_scenario_path",
    "scenario_calibration",
]

log = logging.getLogger(__name__)


class ScenarioError(FieldError):
    """One line: the file, the field and what is wrong (``<source>: <reason>`` when the whole
    file is: not found, not TOML)."""

    def __init__(self, source: str, field: str, reason: str) -> None:
        self.source = source
        super().__init__(source, field, reason)
        if not field:
            self.args = (f"{source}: {reason}",)


def _check(scenario: Scenario, source: str) -> None:
    t = scenario.time
    if t.physics_hz % t.control_hz != 0:
        raise ScenarioError(
            source,
            "time.control_hz",
            f"must divide time.physics_hz ({t.physics_hz}) exactly, got {t.control_hz}",
        )
    _check_vehicles(scenario, source)
    sensor = scenario.sensor.resolved()
    if sensor.saturation_g_m3 is not None and sensor.saturation_g_m3 <= sensor.detection_limit_g_m3:
        raise ScenarioError(
            source,
            "sensor.saturation_g_m3",
            f"must exceed sensor.detection_limit_g_m3 ({sensor.detection_limit_g_m3})",
        )
    if not scenario.plume.sources:
        raise ScenarioError(source, "plume.sources", "at least one source is required")
    _check_env(scenario, source)
    _check_sensor(sensor, source)


def _check_vehicles(scenario: Scenario, source: str) -> None:
    seen: dict[str, int] = {}
    sysids: dict[int, str] = {}
    for i, v in enumerate(scenario.vehicles):
        if v.id in seen:
            raise ScenarioError(
                source,
                f"vehicles[{i}].id",
                f"duplicate vehicle id {v.id!r} (also vehicles[{seen[v.id]}])",
            )
        seen[v.id] = i
        if serves_several(v.id):
            raise ScenarioError(
                source,
                f"vehicles[{i}].id",
                f"{v.id!r} ends like the name of a process serving several vehicles "
                "('<id>-plus<N>'); choose another id",
            )
        try:
            load_vehicle_type(v.type)
        except VehicleTypeError as exc:
            raise ScenarioError(source, f"vehicles[{i}].type", str(exc)) from None
        sysid = sysid_at(i, v)
        if sysid is not None and sysid in sysids:
            raise ScenarioError(
                source, f"vehicles[{i}].sysid", f"sysid {sysid} already used by {sysids[sysid]!r}"
            )
        if sysid is not None:
            sysids[sysid] = v.id
        if v.behavior is not None and ":" not in v.behavior:
            raise ScenarioError(
                source, f"vehicles[{i}].behavior", f"expected 'module:Class', got {v.behavior!r}"
            )


def _check_env(scenario: Scenario, source: str) -> None:
    lo, hi = scenario.env.start_min_enu_m, scenario.env.start_max_enu_m
    for axis, a, b in zip("xyz", lo, hi, strict=True):
        if a > b:
            raise ScenarioError(
                source, "env.start_max_enu_m", f"{axis} {b} is below env.start_min_enu_m's {a}"
            )
    if lo[2] <= 0.0:
        raise ScenarioError(
            source, "env.start_min_enu_m", f"the take-off altitude z must be > 0, got {lo[2]}"
        )


def _check_sensor(sensor: Sensor, source: str) -> None:
    if sensor.gas is not None and sensor.gas not in FORMULAS:
        raise ScenarioError(
            source,
            "sensor.gas",
            f"unknown gas {sensor.gas!r}; known: {', '.join(sorted(FORMULAS))}",
        )
    if sensor.mox is not None and sensor.gas is None:
        raise ScenarioError(
            source, "sensor.gas", "a [sensor.mox] curve is in ppm: name the gas it is for"
        )


def parse_override_value(text: str) -> object:
    """A ``--set`` value: a TOML value (``3``, ``2.5``, ``true``, ``[1, 2]``, ``"x"``), else the
    text itself as a string (``--set sensor.preset=pid``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_overrides(raw: dict[str, object], overrides: Iterable[str], source: str) -> None:
    """Set each ``section.key=value`` (dotted: ``plume.filament.count=50``) in the raw TOML
    table ``raw``; the result is validated with the rest of the file."""
    for item in overrides:
        key, eq, value = item.partition("=")
        key = key.strip()
        if not eq or not re.fullmatch(r"[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)+", key):
            raise ScenarioError(source, key or item, f"expected section.key=value (--set {item!r})")
        *sections, name = key.split(".")
        table: dict[str, object] = raw
        for i, section in enumerate(sections):
            sub = table.setdefault(section, {})
            if not isinstance(sub, dict):
                where = ".".join(sections[: i + 1])
                raise ScenarioError(source, key, f"{where} is not a table, cannot set {name}")
            table = sub
        table[name] = parse_override_value(value.strip())


def read_renamed_keys(raw: dict[str, object], source: str) -> None:
    """Move every old key of :data:`RENAMED_KEYS` in the raw TOML table ``raw`` to its new
    name, logging one line per renamed key; both names in one table is an error."""
    seen: set[str] = set()
    for path, table in _tables(raw, ""):
        for old, new in RENAMED_KEYS.get(path.rpartition(".")[2], {}).items():
            if old not in table:
                continue
            if new in table:
                raise ScenarioError(source, f"{path}.{old}", f"renamed {new}: give only {new}")
            table[new] = table.pop(old)
            where = re.sub(r"\[\d+\]", "", path)
            if f"{where}.{old}" not in seen:
                seen.add(f"{where}.{old}")
                _deprecated(source, f"{where}.{old}", f"{where}.{new}")


def _tables(table: dict[str, object], path: str) -> Iterator[tuple[str, dict[str, object]]]:
    """Every table in ``table`` (itself included) with its dotted path (lists as ``[i]``)."""
    yield path, table
    for key, value in table.items():
        inner = f"{path}.{key}" if path else key
        items = enumerate(value) if isinstance(value, list) else [(None, value)]
        for i, item in items:
            if isinstance(item, dict):
                yield from _tables(item, inner if i is None else f"{inner}[{i}]")


def renamed_override(item: str, source: str) -> str:
    """A ``--set section.key=value`` with an old key of :data:`RENAMED_KEYS` given its new
    name (one line logged), any other unchanged."""
    key, eq, value = item.partition("=")
    *sections, name = key.strip().split(".")
    new = RENAMED_KEYS.get(sections[-1], {}).get(name) if sections and eq else None
    if new is None:
        return item
    _deprecated(source, f"--set {key.strip()}", f"--set {'.'.join([*sections, new])}")
    return f"{'.'.join([*sections, new])}={value}"


def _deprecated(source: str, old: str, new: str) -> None:
    log.warning(
        "%s: %s is deprecated, read as %s (the old name goes in the next release)", source, old, new
    )


def parse_scenario(
    text: str, source: str = "<scenario>", overrides: Iterable[str] = ()
) -> Scenario:
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "", f"not valid TOML: {exc}") from None
    read_renamed_keys(raw, source)
    raw.pop(FAMILY_TABLE, None)  # a randomised family's ranges: read by plumeswarm.gsl.family
    overrides = tuple(renamed_override(item, source) for item in overrides)
    if overrides:
        apply_overrides(raw, overrides, source)
    if raw.get("plume", {}).get("preset") == "novak2018":
        plume = raw.setdefault("plume", {})
        plume.setdefault("coefficients", "novak2018")
        plume.setdefault("stability", "D")
        plume.setdefault(
            "sources",
            [{"x_m": 0.0, "y_m": 0.0, "release_rate_g_s": 10.0, "release_height_m": 10.0}],
        )
        raw.setdefault("wind", {}).setdefault("speed_m_s", 6.0)
        raw["wind"].setdefault("from_deg", 270.0)
    vehicles = raw.get("vehicles")
    if isinstance(vehicles, list) and len(vehicles) > MAX_VEHICLES:
        raise ScenarioError(
            source,
            "vehicles",
            f"at most {MAX_VEHICLES} vehicles per scenario, got {len(vehicles)}",
        )
    try:
        scenario = msgspec.convert(raw, Scenario)
    except msgspec.ValidationError as exc:
        raise ScenarioError(source, *explain(exc, raw, Scenario)) from None
    _check(scenario, source)
    return calibrate_scenario(scenario, source)


def _roughness_m(scenario: Scenario) -> float:
    cal = scenario.plume.calibration
    return 0.1 if cal is None else cal.roughness_m


def scenario_calibration(scenario: Scenario) -> AtmosphereCalibration | None:
    """The derived calibration of a scenario with ``[plume.calibration]``, else None; the wind
    speed and the first source's release height set it, and a ``[wind.turbulence]`` is counted
    in its split. Raises ValueError."""
    cal = scenario.plume.calibration
    if cal is None:
        return None
    plume = scenario.plume
    turbulence = scenario.wind.turbulence
    return derive_calibration(
        plume.stability,
        plume.coefficients,
        scenario.wind.speed_m_s,
        plume.sources[0].release_height_m,
        cal.meander_share,
        cal.roughness_m,
        turbulence_share=0.0 if turbulence is None else turbulence.share,
    )


def _derived_turbulence(scenario: Scenario, source: str) -> WindTurbulence | None:
    """The scenario's ``[wind.turbulence]`` with its intensities, length scale and timescale
    derived from the atmosphere (``[plume]`` stability and coefficients, the wind speed, the
    first source's release height, ``[plume.calibration]``'s roughness or 0.1 m)."""
    turbulence = scenario.wind.turbulence
    if turbulence is None:
        return None
    plume = scenario.plume
    try:
        derived = derive_turbulence(
            plume.stability,
            plume.coefficients,
            scenario.wind.speed_m_s,
            plume.sources[0].release_height_m,
            turbulence.share,
            _roughness_m(scenario),
        )
    except ValueError as exc:
        raise ScenarioError(source, "wind.turbulence", str(exc)) from None
    return msgspec.structs.replace(
        turbulence,
        std_m_s=derived.std_m_s,
        length_scale_m=derived.length_scale_m,
        timescale_s=derived.timescale_s,
    )


def calibrate_scenario(scenario: Scenario, source: str = "<scenario>") -> Scenario:
    """``scenario`` with what its ``[plume.calibration]`` derives: the wind ``model =
    "meander"`` with an Ornstein–Uhlenbeck ``[wind.meander]`` of the derived std and timescale
    (``steady`` for a zero meander share), and ``[plume.filament]``'s ``growth_m2_s`` and
    ``release_rate_hz``; and what a ``[wind.turbulence]`` derives (with or without a
    calibration). Unchanged without either. Idempotent."""
    turbulence = _derived_turbulence(scenario, source)
    if turbulence is not None:
        scenario = msgspec.structs.replace(
            scenario, wind=msgspec.structs.replace(scenario.wind, turbulence=turbulence)
        )
    try:
        derived = scenario_calibration(scenario)
    except ValueError as exc:
        field = "wind.turbulence.share" if "turbulence_share" in str(exc) else "plume.calibration"
        raise ScenarioError(source, field, str(exc)) from None
    if derived is None:
        return scenario
    wind = scenario.wind
    if wind.model == "field":
        raise ScenarioError(
            source, "wind.model", "a calibrated plume derives a uniform meander: use 'meander'"
        )
    if derived.sigma_v_m_s == 0.0:
        wind = msgspec.structs.replace(wind, model="steady")
    else:
        meander = msgspec.structs.replace(
            wind.meander,
            preset=None,
            process="ou",
            std_m_s=derived.sigma_v_m_s,
            timescale_s=derived.timescale_s,
        )
        wind = msgspec.structs.replace(wind, model="meander", meander=meander)
    filament = msgspec.structs.replace(
        scenario.plume.filament,
        growth_m2_s=derived.growth_m2_s,
        release_rate_hz=derived.release_rate_hz,
    )
    plume = msgspec.structs.replace(scenario.plume, filament=filament)
    return msgspec.structs.replace(scenario, wind=wind, plume=plume)


def scenario_hash(scenario: Scenario) -> str:
    """What every host of a run must agree on, as 16 hex digits: SHA-256 of the validated
    scenario's canonical JSON (keys sorted), ``network`` left out (each host has its own
    endpoints and identity). Equal content in two files (comments, order, paths) hashes equal."""
    shared = msgspec.structs.replace(scenario, network=NetworkConfig())
    return hashlib.sha256(msgspec.json.encode(shared, order="sorted")).hexdigest()[:16]


def bundled_scenarios() -> list[str]:
    """The names of the scenarios that ship with plumeswarm: ``swarmbus/scenarios/*.toml`` by
    their stem, then the source-seeking benchmark's environments as ``gsl/<name>``, then its
    tuning environments as ``gsl/tuning/<name>``."""
    gsl, tuning = GSL_ENVIRONMENTS_DIR.name, GSL_TUNING_DIR.name
    return (
        sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
        + sorted(f"{gsl}/{p.stem}" for p in GSL_ENVIRONMENTS_DIR.glob("*.toml"))
        + sorted(f"{gsl}/{tuning}/{p.stem}" for p in GSL_TUNING_DIR.glob("*.toml"))
    )


def _bundled_name(p: Path) -> str | None:
    """The name of ``p`` if it is a bundled scenario's path (``novak2018``, ``gsl/lab_thread``)."""
    if p.suffix != ".toml" or not p.is_relative_to(SCENARIOS_DIR):
        return None
    return p.relative_to(SCENARIOS_DIR).with_suffix("").as_posix()


def _no_such_scenario(name: str) -> ScenarioError:
    """One line: ``name`` is no bundled scenario, the nearest one and every valid name."""
    names = bundled_scenarios()
    bare = [n.rpartition("/")[2] for n in names]  # a benchmark environment by its bench name
    hint = did_you_mean(name, names + bare)
    valid = ", ".join(names)
    return ScenarioError(name, "", f"no such scenario{hint}; valid: {valid}, or a file's path")


def load_scenario(path: str | Path | None = None, overrides: Iterable[str] = ()) -> Scenario:
    """Load and validate a scenario file (default: ``swarmbus/scenarios/novak2018.toml``), with
    ``section.key=value`` overrides applied before validation."""
    p = Path(path) if path is not None else DEFAULT_SCENARIO
    name = _bundled_name(p)
    try:
        text = p.read_text()
    except FileNotFoundError:
        if name is not None:  # a name, not a path: no site-packages path in the message
            raise _no_such_scenario(name) from None
        every = bundled_scenarios()
        top = [n for n in every if "/" not in n]
        raise ScenarioError(
            str(p),
            "",
            f"no such file (bundled scenarios: {', '.join(top)}, and {len(every) - len(top)}"
            " source-seeking environments under gsl/: plumeswarm scenario list)",
        ) from None
    except IsADirectoryError:
        raise ScenarioError(str(p), "", "is a directory, not a scenario file") from None
    except (PermissionError, UnicodeDecodeError, OSError) as exc:
        raise ScenarioError(str(p), "", f"cannot read: {exc}") from None
    return parse_scenario(text, name or str(p), overrides)  # a bundled one by its name


def resolve_scenario_path(name_or_path: str | None) -> Path:
    """A scenario path, or the name of a bundled scenario: ``novak2018``, or a benchmark
    environment as ``gsl/meander_high`` or by its bench name alone, ``meander_high``. An unknown
    name resolves to a bundled path that does not exist (:func:`load_scenario` says which
    names are valid)."""
    if name_or_path is None:
        return DEFAULT_SCENARIO
    p = Path(name_or_path)
    if p.exists() or p.suffix == ".toml":
        return p
    bundled = SCENARIOS_DIR / f"{name_or_path}.toml"
    environment = GSL_ENVIRONMENTS_DIR / f"{name_or_path}.toml"
    if not bundled.is_file() and "/" not in name_or_path and environment.is_file():
        return environment
    if "/" in name_or_path and not name_or_path.startswith(f"{GSL_ENVIRONMENTS_DIR.name}/"):
        return p
    return bundled
