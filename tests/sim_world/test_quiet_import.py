"""No third-party banner: pybullet's C module prints its build time at import, past
``sys.stdout``/``sys.stderr``; plumeswarm imports it through ``sim_world.pybullet_quiet`` only."""

from __future__ import annotations

import re

from tests.support.procs import CORE_PACKAGES, REPO, run_python


def test_importing_the_world_prints_nothing() -> None:
    res = run_python(
        "import sim_world.world; from sim_world.pybullet_quiet import pb;"
        " print(pb.getAPIVersion())",
        60.0,
    )
    assert res.returncode == 0, res.stderr
    assert res.stdout.strip().isdigit(), res.stdout  # only what the script printed
    assert "build time" not in res.stderr and res.stderr == ""


def test_an_environment_episode_step_prints_nothing_but_the_script() -> None:
    code = (
        "import gymnasium\n"
        "env = gymnasium.make('plumeswarm.envs:plumeswarm/PlumeSource-v0')\n"
        "obs, _ = env.reset(seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "env.close()\n"
        "print('ok')\n"
    )
    res = run_python(code, 120.0)
    assert res.returncode == 0, res.stderr
    assert (res.stdout, res.stderr) == ("ok\n", "")


def test_pybullet_is_imported_only_through_the_quiet_helper() -> None:
    pattern = re.compile(r"^\s*(import pybullet|from pybullet\b)", re.MULTILINE)
    helper = REPO / "sim_world" / "pybullet_quiet.py"
    offenders = [
        str(path.relative_to(REPO))
        for pkg in [*CORE_PACKAGES, "plumeswarm"]
        for path in (REPO / pkg).rglob("*.py")
        if path != helper and pattern.search(path.read_text())
    ]
    assert offenders == []
