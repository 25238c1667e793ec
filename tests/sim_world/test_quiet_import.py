"""No third-party banner: pybullet's C module prints its build time at import, past
``sys.stdout``/``sys.stderr``; plumeswarm imports it through ``sim_world.pybullet_quiet`` only."""

from __future__ import annotations

import os
import re
import subprocess
import sys

from tests.support.procs import REPO

PACKAGES = [
    "swarmbus",
    "sim_world",
    "agents",
    "plume_service",
    "gcs_bridge",
    "recorder",
    "ros2_bridge",
    "deploy",
]


def test_importing_the_world_prints_nothing() -> None:
    res = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sim_world.world; from sim_world.pybullet_quiet import pb;"
            " print(pb.getAPIVersion())",
        ],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().isdigit(), res.stdout  # only what the script printed
    assert "build time" not in res.stderr and res.stderr == ""


def test_an_environment_episode_step_prints_nothing_but_the_script() -> None:
    code = (
        "import gymnasium\n"
        "env = gymnasium.make('experiments.envs:plumeswarm/PlumeSource-v0')\n"
        "obs, _ = env.reset(seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "env.close()\n"
        "print('ok')\n"
    )
    res = subprocess.run(
        [sys.executable, "-c", code],
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    assert (res.stdout, res.stderr) == ("ok\n", "")


def test_pybullet_is_imported_only_through_the_quiet_helper() -> None:
    pattern = re.compile(r"^\s*(import pybullet|from pybullet\b)", re.MULTILINE)
    helper = REPO / "sim_world" / "pybullet_quiet.py"
    offenders = [
        str(path.relative_to(REPO))
        for pkg in [*PACKAGES, "experiments", "bench"]
        for path in (REPO / pkg).rglob("*.py")
        if path != helper and pattern.search(path.read_text())
    ]
    assert offenders == []
