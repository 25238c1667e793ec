"""What a ``pip install plumeswarm`` gets: the core dependencies cover every module the core
imports, each optional module is in the extra its error names, and a missing extra is one line.
(The wheel itself, in an environment of its own: tests/system/test_wheel.py.)
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
from importlib.metadata import distribution, packages_distributions

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from swarmbus.extras import EXTRA_OF_MODULE
from tests.support.procs import CORE_PACKAGES, REPO, run_python

PROJECT = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
OURS = {*CORE_PACKAGES, "plumeswarm", "tests"}


def names(requirements: list[str]) -> set[str]:
    return {
        re.split(r"[<>=!\[; ]", r, maxsplit=1)[0].lower().replace("_", "-") for r in requirements
    }


def imported_modules(package: str) -> set[str]:
    found: set[str] = set()
    for path in (REPO / package).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name.partition(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.partition(".")[0])
    return found - OURS - set(sys.stdlib_module_names) - {"__future__"}


def distributions_of(module: str) -> set[str]:
    return {d.lower().replace("_", "-") for d in packages_distributions().get(module, [])}


def test_every_module_the_core_imports_is_a_core_dependency_or_a_named_extra() -> None:
    core = names(PROJECT["dependencies"])
    extras = {k: names(v) for k, v in PROJECT["optional-dependencies"].items()}
    missing = []
    for package in CORE_PACKAGES:
        for module in sorted(imported_modules(package)):
            dists = distributions_of(module)
            assert dists, f"{package} imports {module}, which no installed distribution provides"
            if dists & core:
                continue
            extra = EXTRA_OF_MODULE.get(module)
            if extra is None or not dists & extras[extra]:
                missing.append(f"{package}: {module} ({', '.join(sorted(dists))})")
    assert missing == []


def test_each_optional_module_is_in_the_extra_its_message_names() -> None:
    extras = {k: names(v) for k, v in PROJECT["optional-dependencies"].items()}
    for module, extra in EXTRA_OF_MODULE.items():
        dists = distributions_of(module) or {module.replace("_", "-")}
        assert dists & extras[extra], (module, extra)
        assert not dists & names(PROJECT["dependencies"]), f"{module} is core, not optional"


def run_without(module: str, code: str) -> subprocess.CompletedProcess[str]:
    """``code`` in a fresh interpreter where ``import module`` fails as if not installed."""
    return run_python(f"import sys; sys.modules[{module!r}] = None\n{code}", 60.0)


def test_a_cli_command_without_its_extra_is_one_line_naming_it() -> None:
    res = run_without(
        "matplotlib",
        "from plumeswarm.cli.main import main\n"
        "sys.argv = ['plumeswarm', 'report', 'missing.mcap', '--out', 'r']\nmain()",
    )
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.strip() == (
        "plumeswarm: error: this needs matplotlib, from the 'report' extra: "
        "pip install 'plumeswarm[report]'"
    )


def test_the_environments_without_the_rl_extra_name_it() -> None:
    res = run_without("gymnasium", "import plumeswarm.envs")
    assert res.returncode == 1
    last = res.stderr.strip().splitlines()[-1]
    assert last == (
        "swarmbus.extras.MissingExtra: plumeswarm.envs needs gymnasium, from the 'rl' extra: "
        "pip install 'plumeswarm[rl]'"
    )


def core_closure() -> set[str]:
    """Every distribution ``pip install plumeswarm`` installs: the core requirements and theirs,
    read from the installed distributions' metadata (extras left out, markers evaluated here)."""
    seen: set[str] = set()
    todo = [Requirement(r) for r in PROJECT["dependencies"]]
    while todo:
        req = todo.pop()
        name = canonicalize_name(req.name)
        if name in seen or (req.marker is not None and not req.marker.evaluate({"extra": ""})):
            continue
        seen.add(name)
        todo += [Requirement(r) for r in distribution(name).requires or []]
    return seen


def test_the_core_install_pulls_neither_ray_nor_pytorch_and_train_pins_the_cpu_wheel() -> None:
    closure = core_closure()
    assert len(closure) > len(PROJECT["dependencies"])  # the walk reached their dependencies
    assert not closure & {"ray", "torch", "stable-baselines3"}, closure
    train = [Requirement(r) for r in PROJECT["optional-dependencies"]["train"]]
    # the release whose CPU wheel CI holds: a range would let pip take a newer CUDA build
    assert [str(r.specifier) for r in train if r.name == "torch"] == ["==2.13.0"]
    dev = Requirement(next(r for r in PROJECT["optional-dependencies"]["dev"] if "[" in r))
    assert "train" in dev.extras  # make test's venv (the dev extra) trains
