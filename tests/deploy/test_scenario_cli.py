"""``plumeswarm scenario list/show/schema`` and ``--set section.key=value``: real subprocesses.

Expected values come from the TOML files read independently (``tomllib``), never from the
code that prints them.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from swarmbus.scenario import SCENARIOS_DIR, load_scenario, parse_scenario
from tests.support.procs import run_cli

BUNDLED = sorted(p.stem for p in SCENARIOS_DIR.glob("*.toml"))
# the benchmark environments, by the names `bench gsl --environments` takes
ENVIRONMENTS = sorted(p.stem for p in (SCENARIOS_DIR / "gsl").glob("*.toml"))
# the environments tuning uses, never published
TUNING = sorted(p.stem for p in (SCENARIOS_DIR / "gsl" / "tuning").glob("*.toml"))


def test_list_names_every_bundled_scenario_with_its_vehicle_count() -> None:
    res = run_cli(["scenario", "list"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert [ln.split()[0] for ln in lines] == BUNDLED + [f"gsl/{e}" for e in ENVIRONMENTS] + [
        f"gsl/tuning/{e}" for e in TUNING
    ]
    assert len(ENVIRONMENTS) >= 6 and len(TUNING) >= 2
    for line in lines:
        raw = tomllib.loads((SCENARIOS_DIR / f"{line.split()[0]}.toml").read_text())
        assert f"{len(raw['vehicles'])} vehicle(s)" in line


def test_list_dir_lists_its_files_and_marks_an_invalid_one(tmp_path: Path) -> None:
    (tmp_path / "mine.toml").write_text((SCENARIOS_DIR / "novak2018.toml").read_text())
    (tmp_path / "broken.toml").write_text("[time]\nphysics_hz = 'fast'\n")
    res = run_cli(["scenario", "list", "--dir", str(tmp_path)], timeout_s=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert [ln.split()[0] for ln in lines] == ["broken", "mine"]
    assert "invalid: time.physics_hz" in lines[0]
    assert "3 vehicle(s)" in lines[1]


@pytest.mark.parametrize("name", BUNDLED)
def test_show_prints_toml_that_loads_back_into_the_same_scenario(name: str) -> None:
    res = run_cli(["scenario", "show", name], timeout_s=60)
    assert res.returncode == 0, res.stderr
    shown = tomllib.loads(res.stdout)
    assert shown["time"]["physics_hz"] > 0  # a default the bundled file may not spell out
    assert parse_scenario(res.stdout, "shown") == load_scenario(SCENARIOS_DIR / f"{name}.toml")


def test_set_overrides_show_and_check() -> None:
    res = run_cli(
        [
            "scenario",
            "show",
            "filament",
            "--set",
            "wind.speed_m_s=3.5",
            "--set",
            "sensor.preset=pid",
        ],
        timeout_s=60,
    )
    assert res.returncode == 0, res.stderr
    shown = tomllib.loads(res.stdout)
    assert shown["wind"]["speed_m_s"] == 3.5
    assert shown["sensor"]["preset"] == "pid"
    raw = tomllib.loads((SCENARIOS_DIR / "filament.toml").read_text())
    assert shown["world"]["name"] == raw["world"]["name"]  # the rest is the file's


def test_schema_accepts_the_bundled_files_and_rejects_a_wrong_type() -> None:
    res = run_cli(["scenario", "schema"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    schema = json.loads(res.stdout)
    for name in BUNDLED:
        jsonschema.validate(tomllib.loads((SCENARIOS_DIR / f"{name}.toml").read_text()), schema)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({"time": {"physics_hz": "fast"}}, schema)


def test_check_of_an_unknown_name_lists_the_bundled_ones_and_no_path() -> None:
    res = run_cli(["scenario", "check", "nosuch"], timeout_s=60)
    assert res.returncode != 0
    line = res.stderr.strip()
    assert len(line.splitlines()) == 1, res.stderr
    assert line.startswith("plumeswarm: error: nosuch: no such scenario; valid: "), line
    valid = line.split("; valid: ", 1)[1].split(", ")
    assert set(BUNDLED + [f"gsl/{e}" for e in ENVIRONMENTS]) <= set(valid), line
    assert "<file>" not in line and "did you mean" not in line, line
    assert str(SCENARIOS_DIR.parent) not in line and " /" not in line, line  # no install path


@pytest.mark.parametrize(("typed", "meant"), [("novak", "novak2018"), ("filamnet", "filament")])
def test_a_near_miss_name_gets_a_did_you_mean(typed: str, meant: str) -> None:
    res = run_cli(["scenario", "check", typed], timeout_s=60)
    assert res.returncode != 0
    assert len(res.stderr.strip().splitlines()) == 1, res.stderr
    assert f"did you mean {meant!r}?" in res.stderr, res.stderr


@pytest.mark.parametrize("environment", ENVIRONMENTS)
def test_check_resolves_a_benchmark_environment_by_its_bench_name(environment: str) -> None:
    raw = tomllib.loads((SCENARIOS_DIR / "gsl" / f"{environment}.toml").read_text())
    res = run_cli(["scenario", "check", environment], timeout_s=60)
    assert res.returncode == 0, res.stderr
    assert f"world {raw['world']['name']!r}" in res.stdout, res.stdout


def test_show_resolves_a_benchmark_environment_by_its_listed_name() -> None:
    raw = tomllib.loads((SCENARIOS_DIR / "gsl" / "lab_thread.toml").read_text())
    res = run_cli(["scenario", "show", "gsl/lab_thread"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    shown = tomllib.loads(res.stdout)
    assert raw["world"].items() <= shown["world"].items()
    assert shown["wind"]["speed_m_s"] == raw["wind"]["speed_m_s"]


def test_node_resolves_a_benchmark_environment_by_name() -> None:
    """``node --scenario NAME`` reads the environment (its vehicle id is the file's)."""
    raw = tomllib.loads((SCENARIOS_DIR / "gsl" / "steady_gaussian.toml").read_text())
    res = run_cli(
        ["node", "autopilot", "--scenario", "steady_gaussian", "--vehicle", "nosuch"],
        timeout_s=60,
    )
    assert res.returncode != 0
    ids = ", ".join(sorted(v["id"] for v in raw["vehicles"]))
    assert f"(vehicles: {ids})" in res.stderr, res.stderr
    assert "no such scenario" not in res.stderr


BAD_SETS = {
    "unknown key": ("sensor.bogus=1", "sensor.bogus: unknown key"),
    "near miss": ("wind.sped_m_s=3", "wind.sped_m_s: unknown key (did you mean 'speed_m_s'?)"),
    "bad enum": ("wind.model=turbulent", "wind.model: invalid choice, got 'turbulent'; valid: "),
    "unknown section": ("nosection.x=1", "nosection"),
    "wrong type": ("time.physics_hz=fast", "time.physics_hz: expected integer, got 'fast'"),
    "out of range": ("time.physics_hz=-3", "time.physics_hz"),
    "no value": ("time.physics_hz", "time.physics_hz"),
    "no section": ("seed=3", "seed"),
    "not a table": ("plume.sources.x_m=1", "plume.sources"),
}


COMMANDS = {
    "show": ["scenario", "show", "novak2018"],
    "demo": ["demo", "--out", "{tmp}/run", "--timeout", "30"],
    "up": ["up", "--headless", "--out", "{tmp}/run"],
    "bench-scale": ["bench", "scale", "--vehicles", "1", "--out", "{tmp}/b"],
}
# every command loads through the same loader: all the bad kinds on one, two on the others
CASES = [("show", case) for case in BAD_SETS] + [
    (command, case)
    for command in ("demo", "up", "bench-scale")
    for case in ("unknown key", "wrong type")
]


@pytest.mark.parametrize(("command", "case"), CASES, ids=lambda x: str(x))
def test_a_bad_set_is_one_line_naming_the_key(tmp_path: Path, command: str, case: str) -> None:
    item, named = BAD_SETS[case]
    args = [a.replace("{tmp}", str(tmp_path)) for a in COMMANDS[command]]
    res = run_cli([*args, "--set", item], timeout_s=60)
    shown = f"stdout: {res.stdout}\nstderr: {res.stderr}"
    assert res.returncode != 0, shown
    assert "Traceback" not in res.stderr, shown
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("plumeswarm: error: "), shown
    assert named in lines[0], shown
    assert not (tmp_path / "run").exists() or not any((tmp_path / "run").iterdir()), shown


def _properties(node: object, where: str) -> list[tuple[str, dict[str, object]]]:
    """Every ``properties`` entry anywhere in a JSON Schema, with where it is."""
    found: list[tuple[str, dict[str, object]]] = []
    if isinstance(node, dict):
        for key, prop in (node.get("properties") or {}).items():
            found.append((f"{where}.{key}", prop))
        for key, value in node.items():
            found += _properties(value, f"{where}/{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            found += _properties(value, f"{where}[{i}]")
    return found


def test_schema_describes_every_field_and_every_section() -> None:
    res = run_cli(["scenario", "schema"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    schema = json.loads(res.stdout)
    props = _properties(schema, "")
    # every section of a file is in it (the walk reaches them), with its fields
    raw = tomllib.loads((SCENARIOS_DIR / "filament.toml").read_text())
    named = {where.rsplit(".", 1)[1] for where, _ in props}
    assert set(raw) <= named and set(raw["wind"]) <= named, sorted(named)
    bare = [where for where, prop in props if not str(prop.get("description", "")).strip()]
    assert bare == [], f"fields without a description: {', '.join(bare)}"
    sections = [name for name, d in schema["$defs"].items() if not d.get("description")]
    assert sections == [], f"sections without a description: {', '.join(sections)}"
