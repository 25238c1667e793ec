"""The wheel, installed into a virtual environment of its own: what a user who runs ``pip install
plumeswarm`` imports. The wheel is built from this tree without build isolation (the dev extra
brings the build backend, so no index is needed); its dependencies come from this environment's
site-packages, added as a plain path, so the only plumeswarm code the new environment sees is the
wheel's."""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import zipfile
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.support.procs import REPO

pytestmark = pytest.mark.timeout(600)

# What the wheel installs at the top level (README, "What plumeswarm installs").
TOP_LEVEL = {
    "agents",
    "deploy",
    "gcs_bridge",
    "plume_atmosphere",
    "plume_service",
    "plumeswarm",
    "recorder",
    "ros2_bridge",
    "sim_world",
    "swarmbus",
}


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("dist")
    subprocess.run(
        [sys.executable, "-m", "build", "--wheel", "--no-isolation", "--outdir", str(out), "."],
        cwd=REPO,
        check=True,
        capture_output=True,
        timeout=300,
    )
    (found,) = out.glob("plumeswarm-*.whl")
    return found


@pytest.fixture(scope="module")
def venv(wheel: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    root = tmp_path_factory.mktemp("venv")
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(root)], check=True)
    python = root / "bin" / "python"
    pip = [sys.executable, "-m", "pip", "--python", str(python)]
    subprocess.run(
        [*pip, "install", "-q", "--no-deps", "--no-index", str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    # The dependencies: this environment's site-packages as a plain path (its .pth files, among
    # them the editable install of this tree, are not processed there).
    site = Path(
        subprocess.run(
            [str(python), "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
            check=True,
            capture_output=True,
            text=True,
        ).stdout.strip()
    )
    (site / "deps.pth").write_text(sysconfig.get_path("purelib") + "\n")
    yield root


def run_in(venv: Path, code: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    return subprocess.run(
        [str(venv / "bin" / "python"), "-c", code],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=180,
    )


def test_the_wheel_installs_our_top_level_packages_and_no_generic_others(wheel: Path) -> None:
    with zipfile.ZipFile(wheel) as whl:
        tops = {name.split("/")[0] for name in whl.namelist() if "/" in name}
        (top_level,) = [n for n in whl.namelist() if n.endswith(".dist-info/top_level.txt")]
        listed = set(whl.read(top_level).decode().split())
    assert listed == TOP_LEVEL
    assert {t for t in tops if not t.endswith((".dist-info", ".data"))} == TOP_LEVEL
    assert "experiments" not in listed and "bench" not in listed and "tests" not in listed
    # every package of the tree is in the wheel (a folder without __init__.py would be left out)
    packages = {
        str(init.parent.relative_to(REPO))
        for top in TOP_LEVEL
        for init in (REPO / top).rglob("__init__.py")
    }
    modules = {
        str(path.relative_to(REPO))
        for top in TOP_LEVEL
        for path in (REPO / top).rglob("*.py")
        if "__pycache__" not in path.parts
    }
    with zipfile.ZipFile(wheel) as whl:
        in_wheel = {n for n in whl.namelist() if n.endswith(".py")}
    assert modules <= in_wheel, sorted(modules - in_wheel)[:5]
    assert {f"{p}/__init__.py" for p in packages} <= in_wheel


def test_import_plumeswarm_from_the_wheel(venv: Path, tmp_path: Path) -> None:
    res = run_in(
        venv,
        "import plumeswarm, agents\n"
        "print(plumeswarm.__file__)\n"
        "print(plumeswarm.Swarm.__module__, plumeswarm.GaussianPlume.__name__)\n"
        "print(plumeswarm.load_scenario(None).world.name)\n"
        "print(issubclass(plumeswarm.ScenarioError, plumeswarm.PlumeswarmError))",
        tmp_path,
    )
    assert res.returncode == 0, res.stderr
    where, swarm, world, rooted = res.stdout.split("\n")[:4]
    assert Path(where).is_relative_to(venv), where  # the wheel's copy, not this tree
    assert swarm == "agents.swarm GaussianPlume"
    assert world == "default"
    assert rooted == "True"


def test_gymnasium_makes_the_environment_by_its_module_qualified_id(
    venv: Path, tmp_path: Path
) -> None:
    """A fresh interpreter with nothing of ours imported: Gymnasium imports the module the id
    names (the ``rl`` extra is installed in this environment)."""
    res = run_in(
        venv,
        "import gymnasium\n"
        "env = gymnasium.make('plumeswarm.envs:plumeswarm/PlumeSource-v0')\n"
        "obs, info = env.reset(seed=0)\n"
        "print(type(env.unwrapped).__module__, env.observation_space.contains(obs))\n"
        "env.close()",
        tmp_path,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.split() == ["plumeswarm.envs.source", "True"]


def test_the_console_script_runs(venv: Path, tmp_path: Path) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    res = subprocess.run(
        [str(venv / "bin" / "plumeswarm"), "scenario", "list"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    assert "novak2018" in res.stdout
