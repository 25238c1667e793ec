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


def test_list_names_every_bundled_scenario_with_its_vehicle_count() -> None:
    res = run_cli(["scenario", "list"], timeout_s=60)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert [ln.split()[0] for ln in lines] == BUNDLED
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
    assert "nosuch" in line and all(name in line for name in BUNDLED)
    assert "/" not in line, line  # no install path


BAD_SETS = {
    "unknown key": ("sensor.bogus=1", "bogus"),
    "unknown section": ("nosection.x=1", "nosection"),
    "wrong type": ("time.physics_hz=fast", "time.physics_hz"),
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
