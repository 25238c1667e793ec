"""The packages plumeswarm installs are its own, or the CLI says in one line which are not: another
distribution installing one of its import names, a folder shadowing one, one gone missing. The
developer's editable install and a wheel install pass the check.

Each case is a real interpreter on a real layout: a distribution's ``*.dist-info`` as pip writes
it, setuptools' own editable finder, the packages copied as a wheel installs them."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from plumeswarm._integrity import PACKAGES
from tests.support.procs import REPO

# Run the CLI as ``python -m plumeswarm`` would, after PRELUDE, and say where plumeswarm came from.
RUN_CLI = (
    "import runpy, sys\n"
    "{prelude}\n"
    "import plumeswarm\n"
    "sys.stderr.write('plumeswarm from ' + plumeswarm.__file__ + '\\n')\n"
    "sys.argv = ['plumeswarm', '--help']\n"
    "runpy.run_module('plumeswarm', run_name='__main__', alter_sys=True)\n"
)
# The venv's own editable finder (it may point at another checkout than this one) taken out.
WITHOUT_VENV_FINDER = (
    "sys.meta_path[:] = [f for f in sys.meta_path\n"
    "                    if not getattr(f, '__module__', '').startswith('__editable__')]\n"
)
ADVICE = "use a virtual environment of its own for plumeswarm"


def python(args: list[str], cwd: Path, pythonpath: list[Path]) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath:
        env["PYTHONPATH"] = os.pathsep.join(map(str, pythonpath))
    return subprocess.run(
        [sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=120
    )


def fake_distribution(site: Path, name: str, top_level: str, declared_by: str) -> None:
    """A ``*.dist-info`` of distribution ``name`` that declares the import name ``top_level`` in
    ``top_level.txt`` (setuptools) or only through the files of its ``RECORD`` (other backends,
    e.g. hatchling's wheels)."""
    info = site / f"{name.replace('-', '_')}-1.0.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {name}\nVersion: 1.0\n")
    record = [f"{info.name}/METADATA,,", f"{info.name}/RECORD,,"]
    if declared_by == "top_level.txt":
        (info / "top_level.txt").write_text(f"{top_level}\n")
    else:
        record[:0] = [f"{top_level}/__init__.py,sha256=AAAA,10", f"{top_level}/run.py,,"]
    (info / "RECORD").write_text("\n".join(record) + "\n")


def test_the_cli_runs_when_its_packages_are_its_own() -> None:
    res = python(["-m", "plumeswarm", "--help"], REPO, [REPO])
    assert res.returncode == 0, res.stderr
    assert res.stdout.startswith("Usage: plumeswarm")
    assert res.stderr == ""


@pytest.mark.parametrize("declared_by", ["top_level.txt", "RECORD"])
def test_another_distribution_installing_one_of_its_names_is_one_line(
    tmp_path: Path, declared_by: str
) -> None:
    fake_distribution(tmp_path, "openai-agents", "agents", declared_by)
    res = python(["-m", "plumeswarm", "--help"], REPO, [REPO, tmp_path])
    assert (res.returncode, res.stdout) == (2, "")
    assert res.stderr == (
        "plumeswarm: error: the package 'agents' is also installed by openai-agents, which "
        f"replaces plumeswarm's: {ADVICE}\n"
    )
    assert res.stderr.strip() in (REPO / "README.md").read_text()  # the line it quotes


def test_a_distribution_of_other_names_is_no_collision(tmp_path: Path) -> None:
    fake_distribution(tmp_path, "agents-toolkit", "agents_toolkit", "RECORD")
    res = python(["-m", "plumeswarm", "--help"], REPO, [REPO, tmp_path])
    assert res.returncode == 0, res.stderr


def test_a_folder_shadowing_one_of_its_packages_is_named(tmp_path: Path) -> None:
    (tmp_path / "deploy").mkdir()
    (tmp_path / "deploy" / "__init__.py").write_text("")
    res = python(["-m", "plumeswarm", "--help"], tmp_path, [REPO])  # -m: the cwd comes first
    assert (res.returncode, res.stdout) == (2, "")
    assert res.stderr == (
        f"plumeswarm: error: the package 'deploy' is imported from {tmp_path / 'deploy'}, not "
        f"from plumeswarm's {REPO / 'deploy'}: take {tmp_path} off the Python path (run "
        f"plumeswarm from another folder), or {ADVICE}\n"
    )


def test_the_developers_editable_install_passes(tmp_path: Path) -> None:
    # setuptools' own finder of a PEP 660 editable install, mapping each package to this tree.
    from setuptools.command.editable_wheel import (  # type: ignore[import-untyped]  # no stubs
        _finder_template,
    )

    mapping = {name: str(REPO / name) for name in PACKAGES}
    finder = _finder_template("__editable__.plumeswarm-0.0.0.finder", mapping, {})
    (tmp_path / "__editable___plumeswarm_0_0_0_finder.py").write_text(finder)
    prelude = (
        WITHOUT_VENV_FINDER + f"sys.path.append({str(tmp_path)!r})\n"
        "import __editable___plumeswarm_0_0_0_finder as finder\nfinder.install()"
    )
    work = tmp_path / "work"
    work.mkdir()
    res = python(["-c", RUN_CLI.format(prelude=prelude)], work, [])
    assert res.returncode == 0, res.stderr
    assert res.stderr == f"plumeswarm from {REPO / 'plumeswarm' / '__init__.py'}\n"
    assert res.stdout.startswith("Usage: plumeswarm")


def wheel_install(site: Path) -> None:
    """Our packages as ``pip install plumeswarm-*.whl`` lays them out: the packages side by side
    and ``plumeswarm-*.dist-info`` with its ``top_level.txt`` and ``RECORD``."""
    files = []
    for name in PACKAGES:
        shutil.copytree(REPO / name, site / name, ignore=shutil.ignore_patterns("__pycache__"))
        files += [p.relative_to(site).as_posix() for p in (site / name).rglob("*") if p.is_file()]
    info = site / "plumeswarm-0.0.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: plumeswarm\nVersion: 0.0.0\n")
    (info / "top_level.txt").write_text("\n".join(sorted(PACKAGES)) + "\n")
    (info / "RECORD").write_text("".join(f"{f},,\n" for f in files))


def test_a_wheel_install_passes_and_a_package_removed_from_it_is_named(tmp_path: Path) -> None:
    site = tmp_path / "site"
    wheel_install(site)
    run = RUN_CLI.format(prelude=WITHOUT_VENV_FINDER)
    res = python(["-c", run], tmp_path, [site])
    assert res.returncode == 0, res.stderr
    assert res.stderr == f"plumeswarm from {site / 'plumeswarm' / '__init__.py'}\n"
    assert res.stdout.startswith("Usage: plumeswarm")

    # Uninstalling a distribution that had the same import name removes plumeswarm's files.
    shutil.rmtree(site / "agents")
    res = python(["-c", run], tmp_path, [site])
    assert (res.returncode, res.stdout) == (2, "")
    assert res.stderr.splitlines()[-1] == (
        "plumeswarm: error: the package 'agents' of plumeswarm is missing: reinstall plumeswarm"
    )
