"""What ``plumeswarm bench gsl`` can run: algorithms, environments and sensors, by name.

- **Algorithms** are behaviour plug-ins (``module:Class``, docs/agents.md "Behaviours"): the
  built-in table :data:`BUILTIN_ALGORITHMS`, any behaviour a package registers under the
  entry-point group :data:`ENTRY_POINT_GROUP` (``plumeswarm.behaviors``), and any class named
  on the command line as ``name=module:Class`` — one registry, :func:`resolve_algorithm`. A
  class may say how many vehicles fly it (``vehicles = 3``) and what it follows
  (``source = "…"``), and how far apart its members start across the wind
  (``start_spacing_m = 4.0``); the defaults are 1, "" and 0 (a circle of 2 m).
- **Environments** are scenario files: a name is ``swarmbus/scenarios/gsl/<name>.toml`` (or a
  tuning one, ``gsl/tuning/<name>.toml``), anything
  else a path (:func:`load_environment`). The file gives the plume, the wind and the world; the
  bench adds the vehicles, the sensor, the seed and the protocol. ``section.key=value``
  overrides (:func:`apply_overrides`) change a loaded scenario, for sensitivity sweeps.
- **Sensors** are ``[sensor]`` presets (:data:`SENSORS`): one line per sensor model.
- **Behaviour parameters**: a behaviour's tunables are its class attributes;
  :func:`tuned_behavior` names a subclass with some of them changed, which any runner (the
  kinematic bench, the fused runner, an autopilot process) builds from the name alone
  (:mod:`plumeswarm.gsl.tuned`).
"""

from __future__ import annotations

import functools
import hashlib
import importlib
import inspect
import json
import logging
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from importlib.metadata import entry_points
from pathlib import Path
from typing import Any

import msgspec

from plumeswarm.gsl.family import Family, FamilyError
from swarmbus.errors import PlumeswarmError
from swarmbus.scenario import (
    FAMILY_TABLE,
    GSL_ENVIRONMENTS_DIR,
    GSL_TUNING_DIR,
    SENSOR_PRESETS,
    Scenario,
    ScenarioError,
    Sensor,
    parse_scenario,
)
from swarmbus.scenario_errors import did_you_mean, explain

log = logging.getLogger(__name__)

ENTRY_POINT_GROUP = "plumeswarm.behaviors"
ENVIRONMENTS_DIR = GSL_ENVIRONMENTS_DIR
TUNED_MODULE = "plumeswarm.gsl.tuned"


class GslError(PlumeswarmError, ValueError):
    """A bad option: one line naming it and the bad value."""


@dataclass(frozen=True)
class Algorithm:
    behavior: str  # "module:Class"
    vehicles: int = 1
    source: str = ""  # the publication it follows
    start_spacing_m: float = 0.0  # a swarm's starts: a crosswind line this far apart; 0: a circle


BUILTIN_ALGORITHMS: dict[str, Algorithm] = {
    "random_walk": Algorithm(
        "agents.behaviors.random_walk:RandomWalk", 1, "Codling et al. 2008 (floor)"
    ),
    "casting": Algorithm("agents.behaviors.casting:Casting", 1, "Kennedy & Marsh 1974"),
    "surge_cast": Algorithm(
        "agents.behaviors.surge_cast:SurgeCast", 1, "Lochmatter & Martinoli 2008"
    ),
    "gradient_swarm": Algorithm(
        "agents.behaviors.gradient_swarm:GradientSwarm", 3, "Ögren, Fiorelli & Leonard 2004"
    ),
    "infotaxis": Algorithm(
        "agents.behaviors.infotaxis:Infotaxis", 1, "Vergassola, Villermaux & Shraiman 2007"
    ),
    "particle_filter": Algorithm(
        "agents.behaviors.particle_filter:ParticleFilter", 1, "Hutchinson, Oh & Chen 2017"
    ),
    "coop_surge_cast": Algorithm(
        "agents.behaviors.coop_surge_cast:CooperativeSurgeCast",
        3,
        "Lochmatter & Martinoli 2008; detections shared over the radio",
        4.0,
    ),
    "coop_declare": Algorithm(
        "agents.behaviors.coop_declare:CooperativeDeclaration",
        3,
        "Lochmatter & Martinoli 2008; detections and empty casts pooled (Durve et al. 2020)",
        4.0,
    ),
    "coop_infotaxis": Algorithm(
        "agents.behaviors.coop_infotaxis:CooperativeInfotaxis",
        3,
        "Vergassola, Villermaux & Shraiman 2007 infotaxis; every step's observation shared "
        "(collaborative infotaxis, Song et al., J. Phys. A)",
        4.0,
    ),
    "coop_ste": Algorithm(
        "agents.behaviors.coop_ste:CooperativeSTE",
        3,
        "source-term estimation (Hutchinson, Oh & Chen 2017); readings shared over the radio",
        4.0,
    ),
    "oracle": Algorithm("agents.behaviors.oracle:Oracle", 1, "knows the source (ceiling)"),
}

#: Run in every cell whatever ``--algorithms`` says: the floor first, the ceiling last.
FLOOR, CEILING = "random_walk", "oracle"


def _class_of(behavior: str) -> type:
    module_name, sep, class_name = behavior.partition(":")
    if not sep or not module_name or not class_name:
        raise GslError(f"algorithm {behavior!r}: expected 'module:Class'")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError) as exc:
        raise GslError(f"algorithm {behavior!r}: {exc}") from None
    if not isinstance(cls, type) or not callable(getattr(cls, "step", None)):
        raise GslError(f"algorithm {behavior!r}: not a class with a step() method")
    return cls


def algorithm_from_spec(behavior: str) -> Algorithm:
    """The algorithm of a ``module:Class`` behaviour (imported: its ``vehicles`` and
    ``source`` attributes, if it has them)."""
    cls = _class_of(behavior)
    vehicles = getattr(cls, "vehicles", 1)
    if not isinstance(vehicles, int) or vehicles < 1:
        raise GslError(f"algorithm {behavior!r}: vehicles must be an int >= 1, got {vehicles!r}")
    spacing = getattr(cls, "start_spacing_m", 0.0)
    if not isinstance(spacing, int | float) or spacing < 0.0:
        raise GslError(f"algorithm {behavior!r}: start_spacing_m must be >= 0, got {spacing!r}")
    return Algorithm(behavior, vehicles, str(getattr(cls, "source", "")), float(spacing))


@functools.cache
def registered_algorithms() -> dict[str, Algorithm | str]:
    """Every algorithm by name: the built-ins, then the entry points (``name = module:Class``
    in the group ``plumeswarm.behaviors``; a string until resolved). A built-in's name is
    never taken by an entry point."""
    found: dict[str, Algorithm | str] = dict(BUILTIN_ALGORITHMS)
    for ep in sorted(entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        if ep.name in found:
            log.warning("entry point %s = %s ignored: the name is taken", ep.name, ep.value)
            continue
        found[ep.name] = ep.value
    return found


def resolve_algorithm(text: str) -> tuple[str, Algorithm]:
    """``name`` (registered), ``name=module:Class`` or ``module:Class`` (named after the
    class) → (name, algorithm)."""
    name, sep, behavior = text.partition("=")
    if sep:
        if not name.isidentifier():
            raise GslError(f"--algorithms {text!r}: the name must be an identifier")
        return name, algorithm_from_spec(behavior)
    if ":" in text:
        return text.rpartition(":")[2].lower(), algorithm_from_spec(text)
    registry = registered_algorithms()
    if text not in registry:
        raise GslError(f"--algorithms {text!r}: unknown; valid: {', '.join(registry)}")
    entry = registry[text]
    return text, entry if isinstance(entry, Algorithm) else algorithm_from_spec(entry)


# --- behaviour parameters ---------------------------------------------------------------


def tuned_behavior(behavior: str, params: dict[str, Any]) -> str:
    """``behavior`` with class attributes ``params`` changed, as a ``module:Class`` name that
    :mod:`plumeswarm.gsl.tuned` builds in any process; :class:`GslError` names a parameter
    the class does not have, or a value of another kind."""
    if not params:
        return behavior
    cls = _class_of(behavior)
    for key, value in params.items():
        if key.startswith("_") or not hasattr(cls, key):
            public = sorted(
                k
                for k, v in vars(cls).items()
                if not k.startswith("_") and isinstance(v, int | float | str | bool)
            )
            raise GslError(
                f"behavior.{key}: {cls.__name__} has no such parameter; "
                f"its parameters: {', '.join(public) or 'none'}"
            )
        current = getattr(cls, key)
        if isinstance(current, int | float) != isinstance(value, int | float) or isinstance(
            current, bool
        ) != isinstance(value, bool):
            raise GslError(f"behavior.{key}: {value!r} is not like its default {current!r}")
    encoded = json.dumps(params, sort_keys=True, separators=(",", ":"))
    return f"{TUNED_MODULE}:{behavior}?{encoded}"


#: Class attributes that are not parameters: the names of a behaviour's saved state, and the
#: publication it follows.
NOT_PARAMETERS = frozenset({"own_state", "state_attributes", "source"})


def behavior_parameters(behavior: str) -> dict[str, Any]:
    """The parameters of the behaviour ``behavior`` names, by name: its public class attributes
    (not starting with ``_``) over the class and its bases, the nearest definition winning;
    not its functions, methods, class and static methods and properties, nor
    :data:`NOT_PARAMETERS`. The values its instances set in ``__init__`` are code, not here."""
    found: dict[str, Any] = {}
    seen: set[str] = set()
    for klass in _class_of(behavior).__mro__:
        for name, value in vars(klass).items():
            if name.startswith("_") or name in seen:
                continue
            seen.add(name)
            routine = isinstance(value, classmethod | staticmethod | property)
            if not routine and not inspect.isroutine(value) and name not in NOT_PARAMETERS:
                found[name] = value
    return dict(sorted(found.items()))


def behavior_class_name(behavior: str) -> str:
    """``module:qualname`` of the class ``behavior`` names (a tuned one: its base's)."""
    cls = _class_of(behavior)
    return f"{cls.__module__}:{cls.__qualname__}"


# --- scenario overrides -------------------------------------------------------------------


def parse_value(text: str) -> Any:
    """A command-line value: a TOML literal (``5``, ``0.5``, ``true``, ``"x"``, ``[1, 2]``),
    else the text itself (``large``)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _set(node: Any, keys: Sequence[str], value: Any, field: str) -> None:
    if isinstance(node, list):  # a list of sections (sources): every one of them
        for item in node:
            _set(item, keys, value, field)
        return
    key = keys[0]
    if not isinstance(node, dict) or key not in node:
        valid = ", ".join(sorted(node)) if isinstance(node, dict) else "none"
        hint = did_you_mean(key, list(node)) if isinstance(node, dict) else ""
        raise GslError(f"{field}: no {key!r} there{hint}; valid: {valid}")
    if len(keys) == 1:
        node[key] = value
    else:
        _set(node[key], keys[1:], value, field)


def apply_overrides(scenario: Scenario, overrides: Sequence[tuple[str, Any]]) -> Scenario:
    """``scenario`` with each ``section.key`` set (a key under a list of sections, such as
    ``plume.sources.release_rate_g_s``, is set in every one of them), validated as a
    scenario file is."""
    if not overrides:
        return scenario
    raw = msgspec.to_builtins(scenario)
    for field, value in overrides:
        _set(raw, field.split("."), value, field)
    try:
        return msgspec.convert(raw, Scenario)
    except msgspec.ValidationError as exc:
        where, reason = explain(exc, raw, Scenario)
        raise GslError(f"override {where}: {reason}") from None


# --- environments -------------------------------------------------------------------------


def time_dependent(scenario: Scenario) -> bool:
    """A wind that changes in time, or a plume model other than the steady Gaussian."""
    models = {s.model or scenario.plume.model for s in scenario.plume.sources}
    return scenario.wind.model != "steady" or models != {"gaussian"}


@dataclass(frozen=True)
class Environment:
    name: str
    path: Path
    sha256: str  # of the file's bytes
    description: str  # the file's first comment line
    scenario: Scenario  # with the overrides applied (a family's: its base)
    family: Family | None = None  # a randomised family's ranges (its [randomise] table)

    @property
    def time_dependent(self) -> bool:
        return time_dependent(self.scenario)


def environment_names() -> list[str]:
    """The environments shipped in ``swarmbus/scenarios/gsl``, by name."""
    return sorted(p.stem for p in ENVIRONMENTS_DIR.glob("*.toml"))


def tuning_environment_names() -> list[str]:
    """The tuning environments shipped in ``swarmbus/scenarios/gsl/tuning``, by name: tuning
    uses only these (and seeds >= 1000); no published table uses them."""
    return sorted(p.stem for p in GSL_TUNING_DIR.glob("*.toml"))


def is_published_environment(name_or_path: str) -> bool:
    """Whether ``name_or_path`` is one of the published tables' environments (by name or by
    the path of its bundled file): tuning never uses them."""
    return environment_path(name_or_path).resolve().parent == ENVIRONMENTS_DIR.resolve()


def environment_path(name_or_path: str) -> Path:
    """The file of an environment: its name (``steady_gaussian``, or ``gsl/steady_gaussian`` as
    ``plumeswarm scenario list`` shows it; a tuning one as ``tune_randomised``,
    ``tuning/tune_randomised`` or ``gsl/tuning/tune_randomised``), or a scenario file's path."""
    asked, listed = name_or_path, f"{ENVIRONMENTS_DIR.name}/"
    if name_or_path.startswith(listed) and not Path(name_or_path).is_file():
        name_or_path = name_or_path.removeprefix(listed)
    tuning = f"{GSL_TUNING_DIR.name}/"
    if name_or_path.startswith(tuning) and not Path(name_or_path).is_file():
        name_or_path = name_or_path.removeprefix(tuning)  # tuning/<name>: the tuning file
    elif "/" in name_or_path or name_or_path.endswith(".toml"):
        path = Path(name_or_path)
        if not path.is_file():
            raise GslError(f"--environments {name_or_path!r}: no such file")
        return path
    path = ENVIRONMENTS_DIR / f"{name_or_path}.toml"
    if not path.is_file() and (GSL_TUNING_DIR / f"{name_or_path}.toml").is_file():
        path = GSL_TUNING_DIR / f"{name_or_path}.toml"
    if not path.is_file():
        names = environment_names() + tuning_environment_names()
        hint = did_you_mean(name_or_path, names)
        valid = ", ".join(names)
        raise GslError(f"--environments {asked!r}: unknown{hint}; valid: {valid} or a path")
    return path


def _description(text: str) -> str:
    first = text.lstrip().splitlines()[0] if text.strip() else ""
    return first.lstrip("#").strip() if first.startswith("#") else ""


def load_environment(name_or_path: str, overrides: tuple[tuple[str, Any], ...] = ()) -> Environment:
    """The environment ``name_or_path`` (a file needs no ``[[vehicles]]``: the bench adds
    them) with ``overrides`` applied; :class:`GslError` says what is wrong with it."""
    path = environment_path(name_or_path)
    return _environment(path, path.read_bytes(), overrides)


@functools.cache
def _environment(path: Path, data: bytes, overrides: tuple[tuple[str, Any], ...]) -> Environment:
    text = data.decode()
    raw = tomllib.loads(text)
    family = None
    if FAMILY_TABLE in raw:
        try:
            family = Family.from_table(raw[FAMILY_TABLE], str(path))
        except FamilyError as exc:
            raise GslError(f"--environments {str(path)!r}: {exc}") from None
    if "vehicles" not in raw:  # a placeholder the bench replaces
        text += '\n[[vehicles]]\nid = "uav1"\n'
    try:
        scenario = parse_scenario(text, str(path))
    except ScenarioError as exc:
        raise GslError(f"--environments {str(path)!r}: {exc}") from None
    return Environment(
        name=path.stem,
        path=path,
        sha256=hashlib.sha256(data).hexdigest(),
        description=_description(text),
        scenario=apply_overrides(scenario, overrides),
        family=family,
    )


# --- sensors ------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensorModel:
    description: str
    preset: str  # the [sensor] preset

    @property
    def missing(self) -> str | None:
        known = {"ideal", "novak2018", *SENSOR_PRESETS}
        return None if self.preset in known else f"the [sensor] preset {self.preset!r}"

    @property
    def config(self) -> Sensor:
        return msgspec.convert({"preset": self.preset}, Sensor)


#: The bench's sensor column: name → [sensor] preset. One line adds a sensor.
SENSORS: dict[str, SensorModel] = {
    "ideal": SensorModel("the field's value, no lag, noise or limits", "ideal"),
    "mox": SensorModel("metal-oxide, Figaro TGS2620 (rise 2.96 s, decay 15.71 s)", "mox-tgs2620"),
    "pid": SensorModel("photo-ionisation detector, MiniPID (τ 1.30 s, linear)", "pid"),
}
