"""Process packages meet only through swarmbus; the public surfaces change only on purpose."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.support.procs import REPO, run_cli

PROCESS_PACKAGES = ["sim_world", "agents", "plume_service", "gcs_bridge", "deploy"]


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


@pytest.mark.parametrize("package", [p for p in PROCESS_PACKAGES if p != "deploy"])
def test_process_packages_do_not_import_each_other(package: str) -> None:
    others = set(PROCESS_PACKAGES) - {package}
    bad = []
    for path in sorted((REPO / package).rglob("*.py")):
        hits = _imports(path) & others
        if hits:
            bad.append(f"{path.relative_to(REPO)} imports {sorted(hits)}")
    assert not bad, "process packages must meet only through swarmbus: " + "; ".join(bad)


def test_swarmbus_imports_no_process_package() -> None:
    for path in sorted((REPO / "swarmbus").rglob("*.py")):
        assert not (_imports(path) & set(PROCESS_PACKAGES)), path


def test_key_expressions_are_built_only_in_swarmbus_keys() -> None:
    offenders = []
    for package in [*PROCESS_PACKAGES, "swarmbus"]:
        for path in (REPO / package).rglob("*.py"):
            if path == REPO / "swarmbus" / "keys.py":
                continue
            if '"plumeswarm/' in path.read_text() or "'plumeswarm/" in path.read_text():
                offenders.append(str(path.relative_to(REPO)))
    assert not offenders, offenders


PUBLIC_COMMANDS = {
    "up",
    "demo",
    "status",
    "node",
    "plume",
    "scenario",
    "record",
    "replay",
    "report",
    "bench",
    "certs",
    "export",
}


def test_cli_lists_the_public_commands() -> None:
    res = run_cli(["--help"])
    assert res.returncode == 0
    listed = set()
    in_commands = False
    for line in res.stdout.splitlines():
        if line.strip() == "Commands:":
            in_commands = True
            continue
        if in_commands and line.startswith("  ") and line.strip():
            listed.add(line.split()[0])
    assert listed == PUBLIC_COMMANDS


def test_node_roles_are_the_designed_ones() -> None:
    from deploy.roles import ROLES

    assert set(ROLES) == {
        "router",
        "plume",
        "physics",
        "autopilot",
        "gateway",
        "viewer",
        "recorder",
        "foxglove",
    }
