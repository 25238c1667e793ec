"""One error root: every exception class of ours derives from ``PlumeswarmError`` and still from
the built-in it stands for, so ``except PlumeswarmError`` catches all of them and
``except ValueError`` (or ``RuntimeError``, ``TimeoutError``, …) callers keep working."""

from __future__ import annotations

import ast
import builtins
import importlib
import inspect
import json
import os
import subprocess
import sys
import types
from typing import Any

import pytest

from swarmbus.errors import PlumeswarmError
from swarmbus.extras import MissingExtra
from tests.support.procs import CORE_PACKAGES, REPO, run_python

PACKAGES = [*CORE_PACKAGES, "plumeswarm"]
ROOT = "swarmbus.errors.PlumeswarmError"
BUILTIN_EXCEPTIONS = {
    name
    for name, value in vars(builtins).items()
    if inspect.isclass(value) and issubclass(value, BaseException)
}

# What each error stood for before it had a root (read from the code as it was): its callers
# catch it by this built-in, so it stays a base.
BUILTIN_OF: dict[str, type[BaseException]] = {
    "swarmbus.extras.MissingExtra": ImportError,
    "swarmbus.keys.KeyNameError": ValueError,
    "swarmbus.options.OptionError": ValueError,
    "swarmbus.reqrep.Refused": ValueError,
    "swarmbus.reqrep.NoReply": TimeoutError,
    "swarmbus.session.NetworkConfigError": ValueError,
    "swarmbus.vehicle_types.VehicleTypeError": ValueError,
    "swarmbus.scenario.ScenarioError": ValueError,
    "swarmbus.codec.MessageError": ValueError,
    "sim_world.checkpoint.CheckpointError": ValueError,
    "agents.behavior.BehaviorError": RuntimeError,
    "agents.checkpoint_store.CheckpointError": ValueError,
    "agents.swarm_clients.CommandTimeout": TimeoutError,
    "agents.swarm_clients.WaitTimeout": TimeoutError,
    "agents.mission.MissionError": ValueError,
    "gcs_bridge.mission.MissionError": ValueError,
    "gcs_bridge.params.ParamError": ValueError,
    "recorder.handshake.RecorderNotListening": TimeoutError,
    "recorder.reader.RecordingError": RuntimeError,
    "recorder.reader.ExportError": RuntimeError,
    "recorder.replay.ReplayError": RuntimeError,
    "recorder.report.ReportError": RuntimeError,
    "recorder.segments.SegmentError": ValueError,
    "ros2_bridge.wire.WireError": ValueError,
    "deploy.certs.CertError": ValueError,
    "deploy.hosts.HostsError": ValueError,
    "deploy.launcher.LaunchError": RuntimeError,
    "deploy.roles.RoleUnavailable": RuntimeError,
    "deploy.status.NothingRunning": RuntimeError,
    "plumeswarm.gsl.registry.GslError": ValueError,
    "plumeswarm.experiments.chaos.ChaosError": RuntimeError,
    "plumeswarm.experiments.demo.DemoError": RuntimeError,
    "plumeswarm.experiments.driver.DriverError": RuntimeError,
    "plumeswarm.bench.pomdp.PomdpError": ValueError,
    "plumeswarm.survey.pattern.SurveyError": ValueError,
    "plumeswarm.bench.pyflyt.BenchError": RuntimeError,
    "plumeswarm.bench.scale.ScaleError": RuntimeError,
}


def our_modules() -> list[str]:
    """Every module of our packages, by its dotted name (found on disk, not by importing, so a
    folder without ``__init__.py`` is walked too)."""
    names = []
    for package in PACKAGES:
        for path in (REPO / package).rglob("*.py"):
            parts = path.relative_to(REPO).with_suffix("").parts
            names.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return sorted(names)


def import_ours(name: str) -> types.ModuleType | None:
    """The module, or None where it cannot be imported here: a ``__main__`` (importing runs it)
    or a module of a missing optional dependency. Anything else that fails, fails the test."""
    if name.rpartition(".")[2] == "__main__":
        return None
    try:
        return importlib.import_module(name)
    except MissingExtra:
        return None
    except ModuleNotFoundError as exc:
        if (exc.name or "").partition(".")[0] in PACKAGES:
            raise
        return None


def rootless_classes(module: types.ModuleType) -> list[str]:
    """The exception classes defined in ``module`` that do not derive from the root."""
    return [
        f"{module.__name__}.{name}"
        for name, value in vars(module).items()
        if inspect.isclass(value)
        and issubclass(value, BaseException)
        and value.__module__ == module.__name__
        and not issubclass(value, PlumeswarmError)
    ]


def rootless_in_source(source: str, where: str) -> list[str]:
    """The classes of ``source`` built on built-in exceptions alone, without the root (read as
    text: for a module that cannot be imported here, and for classes defined in functions)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.ClassDef) and node.bases:
            bases = {b.id if isinstance(b, ast.Name) else "" for b in node.bases}
            if bases <= BUILTIN_EXCEPTIONS and f"{where}.{node.name}" != ROOT:
                found.append(f"{where}.{node.name}")
    return found


def source_of(name: str) -> str:
    path = REPO / name.replace(".", "/")
    return (path / "__init__.py" if path.is_dir() else path.with_suffix(".py")).read_text()


def scan() -> dict[str, Any]:
    """Every exception class defined in our importable modules (qualified name -> its MRO as
    qualified names), the rootless ones, and the modules read only as source. Run in a fresh
    interpreter: importing everything of ours loads every optional library, with their warnings."""
    classes: dict[str, list[str]] = {}
    rootless: list[str] = []
    unimported: list[str] = []
    for name in our_modules():
        rootless += rootless_in_source(source_of(name), name)  # nested classes too
        module = import_ours(name)
        if module is None:
            unimported.append(name)
            continue
        rootless += [n for n in rootless_classes(module) if n not in rootless]
        for attr, value in vars(module).items():
            ours = inspect.isclass(value) and value.__module__ == name
            if ours and issubclass(value, BaseException):
                mro = [f"{c.__module__}.{c.__qualname__}" for c in value.__mro__]
                classes[f"{name}.{attr}"] = mro
    return {"classes": classes, "rootless": rootless, "unimported": unimported}


@pytest.fixture(scope="module")
def scanned() -> dict[str, Any]:
    res = run_python(
        "import json\nfrom tests.system.test_errors import scan\nprint(json.dumps(scan()))"
    )
    assert res.returncode == 0, res.stderr
    found: dict[str, Any] = json.loads(res.stdout.splitlines()[-1])
    return found


def recorded(scanned: dict[str, Any]) -> dict[str, type[BaseException]]:
    """:data:`BUILTIN_OF`, less the errors of modules read only as source (a lean install
    without an extra)."""
    return {
        name: builtin
        for name, builtin in BUILTIN_OF.items()
        if name.rpartition(".")[0] not in scanned["unimported"]
    }


def test_every_exception_class_of_ours_derives_from_the_root(scanned: dict[str, Any]) -> None:
    assert scanned["rootless"] == []
    classes = scanned["classes"]
    assert all(ROOT in mro for mro in classes.values())  # the scan's own issubclass, read back
    # The scan saw them all: each error recorded above was found where it is defined.
    assert set(recorded(scanned)) <= set(classes), set(recorded(scanned)) - set(classes)


def test_each_error_is_still_the_builtin_it_stands_for(scanned: dict[str, Any]) -> None:
    classes = scanned["classes"]
    wrong = [
        f"{name} is not a {builtin.__name__}"
        for name, builtin in recorded(scanned).items()
        if f"builtins.{builtin.__name__}" not in classes[name]
    ]
    assert wrong == []


def test_an_export_error_is_one_class(scanned: dict[str, Any]) -> None:
    named = [n for n in scanned["classes"] if n.rpartition(".")[2] == "ExportError"]
    assert named == ["recorder.reader.ExportError"]


def test_the_check_flags_a_class_without_the_root() -> None:
    module = types.ModuleType("plumeswarm.example_errors")
    exec(
        "from swarmbus.errors import PlumeswarmError\n"
        "class Loose(ValueError): pass\n"
        "class Rooted(PlumeswarmError, ValueError): pass\n",
        vars(module),
    )
    assert rootless_classes(module) == ["plumeswarm.example_errors.Loose"]
    source = (
        "class Loose(RuntimeError): pass\n"
        "class Rooted(PlumeswarmError, TimeoutError): pass\n"
        "def f():\n"
        "    class Nested(ValueError, KeyError): pass\n"
        "    class OfOurs(Rooted, KeyError): pass\n"
    )
    assert rootless_in_source(source, "m") == ["m.Loose", "m.Nested"]


# The real command line with three commands added that fail as a command body can: an error of
# ours it did not catch (one with a message over two lines), and a bug.
FAILING_CLI = """
import sys
from plumeswarm.cli.main import cli, main
from agents.swarm_clients import WaitTimeout
from swarmbus.scenario import ScenarioError

@cli.command("bad-field")
def bad_field():
    raise ScenarioError("s.toml", "wind.speed_m_s", "must be >= 0, got -1")

@cli.command("timed-out")
def timed_out():
    raise WaitTimeout("no state of uav1\\n  within 5 s")

@cli.command("bug")
def bug():
    raise RuntimeError("a bug")

sys.argv = ["plumeswarm", *sys.argv[1:]]
main()
"""


def run_failing_cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", FAILING_CLI, *args],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize(
    ("command", "line"),
    [
        ("bad-field", "plumeswarm: error: s.toml: wind.speed_m_s: must be >= 0, got -1"),
        ("timed-out", "plumeswarm: error: no state of uav1 within 5 s"),
    ],
)
def test_the_cli_prints_an_error_of_ours_as_one_line_with_status_2(command: str, line: str) -> None:
    res = run_failing_cli(command)
    assert (res.returncode, res.stdout, res.stderr) == (2, "", line + "\n")


def test_the_cli_leaves_click_errors_and_bugs_as_they_were() -> None:
    res = run_failing_cli("no-such-command")  # click's usage error
    assert res.returncode == 2
    assert res.stderr.startswith("Usage: plumeswarm") and "No such command" in res.stderr
    res = run_failing_cli("bug")  # not an error of ours: the traceback a bug report needs
    assert res.returncode == 1
    assert "Traceback" in res.stderr and res.stderr.endswith("RuntimeError: a bug\n")
