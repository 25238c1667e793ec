"""Process packages meet only through swarmbus; the public surfaces change only on purpose."""

from __future__ import annotations

import ast
import re
import tomllib
from collections.abc import Mapping
from pathlib import Path

import pytest

from tests.support.procs import PROCESS_PACKAGES, REPO, run_cli

# Layers, lowest first (docs/architecture.md, "Layers"): a module imports only from its own
# layer or below, by an import statement or by naming a module in a string (``"pkg.mod:main"``,
# ``importlib.import_module("pkg.mod")``), and a role never imports another role. The shared
# models sit at the very bottom, beside the contract: pure science that imports nothing of ours.
LAYERS: list[tuple[str, list[str]]] = [
    ("models", ["plume_atmosphere"]),
    ("contract", ["swarmbus"]),
    ("roles", PROCESS_PACKAGES),
    ("orchestration", ["deploy"]),
    ("experiments", ["plumeswarm.experiments", "plumeswarm.envs", "plumeswarm.gsl"]),
    ("benchmarks", ["plumeswarm.bench"]),
    ("user", ["plumeswarm"]),
]
COMPOSITION = "deploy"
USER = "plumeswarm"
PACKAGES = ["plume_atmosphere", "swarmbus", *PROCESS_PACKAGES, COMPOSITION, USER]
# Ours too, but never imported by the packages: the tests.
TOOLS = ["tests"]


def layer_of(module: str) -> int:
    """The index in :data:`LAYERS` of ``module`` (the most specific prefix wins)."""
    best, best_len = -1, -1
    for index, (_, prefixes) in enumerate(LAYERS):
        for prefix in prefixes:
            if (module == prefix or module.startswith(prefix + ".")) and len(prefix) > best_len:
                best, best_len = index, len(prefix)
    if best < 0:
        raise ValueError(f"{module} is in no layer")
    return best


def layer_violations(graph: Mapping[str, set[str]]) -> list[str]:
    """Each import of ``graph`` that goes up a layer, or from one role to another."""
    bad = []
    for name, targets in sorted(graph.items()):
        for target in sorted(targets):
            up = layer_of(target) > layer_of(name)
            top, other = name.split(".")[0], target.split(".")[0]
            across = top != other and top in PROCESS_PACKAGES and other in PROCESS_PACKAGES
            if up or across:
                bad.append(f"{name} ({LAYERS[layer_of(name)][0]}) imports {target}")
    return bad


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(), filename=str(path))
    out: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.add(node.module.split(".")[0])
    return out


def test_every_package_is_covered() -> None:
    """Each top-level package of the repository, and each one pyproject installs, is one the
    rules below know."""
    on_disk = {p.parent.name for p in REPO.glob("*/__init__.py")}
    assert on_disk == set(PACKAGES) | set(TOOLS)
    project = tomllib.loads((REPO / "pyproject.toml").read_text())
    installed = {
        p.rstrip("*") for p in project["tool"]["setuptools"]["packages"]["find"]["include"]
    }
    assert installed == set(PACKAGES)
    assert set(project["tool"]["mypy"]["packages"]) >= set(PACKAGES)


def test_layer_violations_sees_an_upward_import_and_a_role_importing_a_role() -> None:
    assert layer_violations({"deploy.launcher": {"swarmbus.keys", "sim_world.world"}}) == []
    assert layer_violations({"swarmbus.scenario": {"plume_atmosphere.calibration"}}) == []
    assert layer_violations({"plumeswarm.cli.main": {"plumeswarm.bench.scale"}}) == []
    assert layer_violations({"plumeswarm": {"plumeswarm.experiments.fused"}}) == []
    assert layer_violations({"deploy.launcher": {"plumeswarm.experiments.demo"}}) == [
        "deploy.launcher (orchestration) imports plumeswarm.experiments.demo"
    ]
    assert layer_violations({"plumeswarm.experiments.fused": {"plumeswarm.bench.scale"}}) == [
        "plumeswarm.experiments.fused (experiments) imports plumeswarm.bench.scale"
    ]
    assert layer_violations({"plumeswarm.gsl.bench": {"plumeswarm"}}) == [
        "plumeswarm.gsl.bench (experiments) imports plumeswarm"
    ]
    assert layer_violations({"agents.swarm": {"sim_world.world"}}) == [
        "agents.swarm (roles) imports sim_world.world"
    ]
    assert layer_violations({"swarmbus.keys": {"agents.sensor"}}) == [
        "swarmbus.keys (contract) imports agents.sensor"
    ]
    assert layer_violations({"plume_atmosphere.wind": {"swarmbus.scenario"}}) == [
        "plume_atmosphere.wind (models) imports swarmbus.scenario"
    ]


def test_no_module_imports_a_higher_layer_or_another_role() -> None:
    """Every import of every module of ours, also inside functions, and every module named in a
    string, by the layers above."""
    graph = import_graph(PACKAGES)
    assert len(graph) > 100
    assert layer_violations(graph) == []


def test_a_module_named_in_a_string_counts_as_an_import(tmp_path: Path) -> None:
    """``"pkg.mod:func"`` entries and ``import_module("pkg.mod")`` are edges of the graph, so a
    string reference upwards fails the layer test as an import would."""
    src = tmp_path / "roles.py"
    src.write_text('ROLES = {"x": "plumeswarm.bench.scale:main"}\nM = "plumeswarm.gsl"\n')
    modules = {"plumeswarm.bench.scale": src, "plumeswarm.gsl": src, "deploy.roles": src}
    assert _import_targets("deploy.roles", src, modules) == {
        "plumeswarm.bench.scale",
        "plumeswarm.gsl",
    }
    assert layer_violations({"deploy.roles": _import_targets("deploy.roles", src, modules)}) == [
        "deploy.roles (orchestration) imports plumeswarm.bench.scale",
        "deploy.roles (orchestration) imports plumeswarm.gsl",
    ]
    src.write_text(
        '"""A docstring that names plumeswarm.gsl in passing."""\nKEY = "plumeswarm/x"\n'
    )
    assert _import_targets("deploy.roles", src, modules) == set()


def test_the_models_import_nothing_of_ours() -> None:
    for path in sorted((REPO / "plume_atmosphere").rglob("*.py")):
        assert not (_imports(path) & (set(PACKAGES) - {"plume_atmosphere"})), path


def test_no_top_level_experiments_or_bench_remains() -> None:
    assert not (REPO / "experiments").exists()
    assert not (REPO / "bench").exists()


@pytest.mark.parametrize(
    "name", ["fused", "envs", "gsl_episode", "gsl_bench", "gsl_figure", "demo", "scale_bench"]
)
def test_deploy_holds_no_experiment_or_benchmark(name: str) -> None:
    assert not (REPO / "deploy" / f"{name}.py").exists()
    assert not (REPO / "deploy" / name).exists()


@pytest.mark.parametrize("package", PROCESS_PACKAGES)
def test_process_packages_do_not_import_each_other(package: str) -> None:
    others = {*PROCESS_PACKAGES, COMPOSITION, USER} - {package}
    bad = []
    for path in sorted((REPO / package).rglob("*.py")):
        hits = _imports(path) & others
        if hits:
            bad.append(f"{path.relative_to(REPO)} imports {sorted(hits)}")
    assert not bad, "process packages must meet only through swarmbus: " + "; ".join(bad)


def test_swarmbus_imports_no_process_package() -> None:
    for path in sorted((REPO / "swarmbus").rglob("*.py")):
        assert not (_imports(path) & (set(PACKAGES) - {"swarmbus", "plume_atmosphere"})), path


@pytest.mark.parametrize("package", PACKAGES)
def test_packages_do_not_import_the_tests(package: str) -> None:
    bad = [
        str(path.relative_to(REPO))
        for path in sorted((REPO / package).rglob("*.py"))
        if _imports(path) & set(TOOLS)
    ]
    assert not bad, bad


def _uses_of(path: Path, tool: str) -> list[str]:
    """Where the file at ``path`` imports ``tool`` or names one of its modules in a string (a
    command line such as ``python -m tool.x`` or an import by name)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    hits = sorted(_imports(path) & {tool})
    for node in ast.walk(tree):
        value = node.value if isinstance(node, ast.Constant) else None
        if isinstance(value, str) and value.startswith(f"{tool}."):
            hits.append(repr(value))
    return hits


def test_the_benches_do_not_use_the_tests() -> None:
    """The benches measure the stack with their own code: they neither import the tests nor
    start their modules (``python -m tests.…``)."""
    bad = [
        f"{path.relative_to(REPO)}: {hits}"
        for path in sorted((REPO / "plumeswarm" / "bench").rglob("*.py"))
        if (hits := _uses_of(path, "tests"))
    ]
    assert not bad, bad


def test_uses_of_sees_an_import_and_a_module_started_by_name(tmp_path: Path) -> None:
    src = tmp_path / "x.py"
    src.write_text('import os\nfrom tests.support import procs\nARGS = ["-m", "tests.support.x"]\n')
    assert _uses_of(src, "tests") == ["tests", "'tests.support.x'"]
    src.write_text(
        '"""Unlike tests.support, this docstring names no module."""\nimport testsuite\n'
    )
    assert _uses_of(src, "tests") == []


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _import_targets(name: str, path: Path, modules: Mapping[str, Path]) -> set[str]:
    """The modules of ours that ``name`` imports, at any level of the file (a function's import
    runs too); ``from package import submodule`` points at the submodule."""
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names if alias.name in modules)
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            module = ".".join([*base, *([node.module] if node.module else [])])
            for alias in node.names:
                if f"{module}.{alias.name}" in modules:
                    out.add(f"{module}.{alias.name}")
                elif module in modules:
                    out.add(module)
    out.update(_named_modules(path, modules))
    out.discard(name)
    return out


_MODULE_PATH = re.compile(
    r"[A-Za-z_]\w*(\.[A-Za-z_]\w*)+(:[A-Za-z_]\w*)?|[A-Za-z_]\w*:[A-Za-z_]\w*"
)


def _named_modules(path: Path, modules: Mapping[str, Path]) -> set[str]:
    """The modules of ours that a string constant of ``path`` names in full (``"pkg.mod"``,
    ``"pkg.mod:func"``): entry-point tables and imports by name."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        value = node.value if isinstance(node, ast.Constant) else None
        if isinstance(value, str) and _MODULE_PATH.fullmatch(value):
            module = value.partition(":")[0]
            if module in modules:
                out.add(module)
    return out


def import_graph(packages: list[str]) -> dict[str, set[str]]:
    """Module → the modules of ``packages`` it imports."""
    modules = {
        _module_name(path): path for p in packages for path in sorted((REPO / p).rglob("*.py"))
    }
    return {name: _import_targets(name, path, modules) for name, path in modules.items()}


def find_cycle(graph: Mapping[str, set[str]]) -> list[str]:
    """One cycle of ``graph`` as [a, b, …, a] (depth-first search), or [] when there is none."""
    done: set[str] = set()
    path: list[str] = []
    on_path: set[str] = set()

    def visit(node: str) -> list[str]:
        path.append(node)
        on_path.add(node)
        for nxt in sorted(graph.get(node, ())):
            if nxt in on_path:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in done:
                cycle = visit(nxt)
                if cycle:
                    return cycle
        path.pop()
        on_path.discard(node)
        done.add(node)
        return []

    for start in sorted(graph):
        if start not in done:
            cycle = visit(start)
            if cycle:
                return cycle
    return []


def test_find_cycle_finds_a_cycle_and_only_a_cycle() -> None:
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": set(), "d": {"b", "c"}}) == []
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"x": {"y"}, "y": {"y2"}, "y2": {"y"}}) == ["y", "y2", "y"]
    assert find_cycle({"a": {"a"}}) == ["a", "a"]


def test_import_graph_sees_each_kind_of_import() -> None:
    graph = import_graph(PACKAGES)
    assert "plumeswarm.cli.common" in graph["plumeswarm.cli.plume"]  # inside a function
    assert "recorder.schema" in graph["recorder.reader"]  # from package import submodule
    assert "swarmbus.codec" in graph["swarmbus.node"]


def test_the_import_graph_has_no_cycle() -> None:
    graph = import_graph(PACKAGES)
    assert len(graph) > 100
    assert find_cycle(graph) == []


def test_only_the_cli_parses_arguments_and_nothing_calls_back_into_it() -> None:
    """Tools (demo, benches, status, the recorder's commands) are library functions the CLI
    calls: only ``plumeswarm.cli`` uses click, and only ``python -m plumeswarm`` imports the CLI."""
    graph = import_graph(PACKAGES)
    callers = sorted(
        name
        for name, targets in graph.items()
        if not name.startswith("plumeswarm.cli")
        and any(t.startswith("plumeswarm.cli") for t in targets)
    )
    assert callers == ["plumeswarm.__main__"]
    clicks = sorted(
        str(path.relative_to(REPO))
        for package in PACKAGES
        for path in (REPO / package).rglob("*.py")
        if "click" in _imports(path)
    )
    assert clicks and all(c.startswith("plumeswarm/cli/") for c in clicks), clicks


def test_key_expressions_are_built_only_in_swarmbus_keys() -> None:
    offenders = []
    for package in PACKAGES:
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
    "chaos",
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
        "ros2",
    }
