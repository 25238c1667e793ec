"""Every script in examples/ runs, and what it prints means what it says.

Each runs as a user runs it (``python examples/X.py`` in a fresh interpreter), bounded; the
expected values come from the scenario file (tomllib), from the reward's closed form, or from
what the test itself published, never from the code under test.
"""

from __future__ import annotations

import csv
import math
import os
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest

from swarmbus.scenario import SCENARIOS_DIR
from tests.support.procs import REPO, zenoh_network
from tests.support.recording import recorded_run
from tests.support.upstack import plumeswarm_up

EXAMPLES = REPO / "examples"
NOVAK = tomllib.loads((SCENARIOS_DIR / "novak2018.toml").read_text())
NUM = r"(-?[0-9.]+)"


def run_example(name: str, *args: str, cwd: Path, timeout_s: float = 300.0) -> str:
    res = subprocess.run(
        [sys.executable, str(EXAMPLES / name), *args],
        cwd=cwd,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        capture_output=True,
        text=True,
        timeout=timeout_s,
    )
    assert res.returncode == 0, f"stdout: {res.stdout}\nstderr: {res.stderr[-3000:]}"
    assert res.stderr == "", res.stderr  # quiet: no banner, no warning
    return res.stdout


def window(model_g_m3: float) -> float:
    """The novak2018 sensor (no noise, no lag): 0 below the detection limit, capped above."""
    if model_g_m3 < 0.01:
        return 0.0
    return min(model_g_m3, 0.2)


def test_swarm_script_reads_the_plume_model_at_its_targets(tmp_path: Path) -> None:
    roles = "router,plume,physics,autopilot"
    with plumeswarm_up(None, tmp_path, "--headless", "--stepped", "--roles", roles) as up:
        out = run_example("swarm_script.py", "--connect", up.endpoint, cwd=tmp_path)
    pattern = rf"(uav\d) at \({NUM}, {NUM}, {NUM}\) m reads {NUM} g/m3, the plume model there {NUM}"
    rows = {m[0]: [float(v) for v in m[1:]] for m in re.findall(pattern, out)}
    targets = {"uav1": (40.0, -4.0, 10.0), "uav2": (40.0, 0.0, 10.0), "uav3": (40.0, 4.0, 10.0)}
    assert set(rows) == set(targets), out
    for vid, (x, y, z, reading, model) in rows.items():
        assert max(abs(a - b) for a, b in zip((x, y, z), targets[vid], strict=True)) <= 0.6
        assert reading == pytest.approx(window(model), abs=1.5e-4), out  # printed to 4 places
    # wind from 270 deg: the centreline is y = 0, the Gaussian symmetric about it
    assert rows["uav2"][4] > rows["uav1"][4] > 0.0 and rows["uav2"][4] > rows["uav3"][4] > 0.0
    assert rows["uav1"][4] == pytest.approx(rows["uav3"][4], rel=0.1)


def test_gymnasium_policy_finds_the_source(tmp_path: Path) -> None:
    out = run_example("gymnasium_policy.py", cwd=tmp_path)
    m = re.fullmatch(rf"found the source at t = {NUM} s, {NUM} m away, return {NUM}\n", out)
    assert m, out
    t_s, distance_m, _ = (float(v) for v in m.groups())
    assert distance_m <= NOVAK["env"]["success_radius_m"]
    assert t_s <= 40.0 + NOVAK["env"]["time_limit_s"]  # take-off (at most 40 s) + the episode


def test_pettingzoo_swarm_returns_telescope(tmp_path: Path) -> None:
    out = run_example("pettingzoo_swarm.py", cwd=tmp_path)
    pattern = (
        rf"(uav\d): start {NUM} m, end {NUM} m, found (True|False), crashed (True|False), "
        rf"return {NUM}"
    )
    rows = re.findall(pattern, out)
    assert [r[0] for r in rows] == [v["id"] for v in NOVAK["vehicles"]], out
    for _, start, end, found, crashed, ret in rows:
        # default reward: progress toward the source, +10 on finding it, -10 on a crash
        expected = float(start) - float(end) + 10.0 * (found == "True") - 10.0 * (crashed == "True")
        assert float(ret) == pytest.approx(expected, abs=0.02), out
        if found == "True":
            assert float(end) <= NOVAK["env"]["success_radius_m"]
    assert any(found == "True" for _, _, _, found, _, _ in rows), out


def test_read_recording_counts_what_was_published(tmp_path: Path) -> None:
    recording = tmp_path / "flight.mcap"
    with zenoh_network() as (net, _):
        recorded_run(
            net, tmp_path, recording, "--vehicles", "uav1,uav2", "--steps", "120", "--every", "4"
        )
    out = run_example("read_recording.py", str(recording), cwd=tmp_path)
    pattern = (
        rf"(uav\d): (\d+) states over {NUM} s, flew {NUM} m, max altitude {NUM} m, (\d+) reading"
    )
    rows = {m[0]: m for m in re.findall(pattern, out)}
    assert set(rows) == {"uav1", "uav2"}, out
    for vid, states, _, _, _, readings in rows.values():
        assert (int(states), int(readings)) == (120, 30), vid  # 120 steps, a reading every 4th
    try:
        import pandas  # noqa: F401
    except ImportError:
        assert "pandas:" not in out
    else:
        assert "pandas: 240 rows" in out


def train_tiny(tmp_path: Path, out: str, script: str = "train_sb3.py", envs: int = 2) -> str:
    """A tiny budget: 3-s episodes, 256 steps in 64-step rollouts over ``envs`` copies."""
    return run_example(
        script,
        *("--envs", str(envs), "--steps", "256", "--n-steps", "64", "--episodes", "1"),
        *("--set", "env.time_limit_s=3", "--out", str(tmp_path / out)),
        cwd=tmp_path,
    )


def test_train_sb3_trains_saves_reloads_and_evaluates(tmp_path: Path) -> None:
    out = train_tiny(tmp_path, "run")
    pattern = (
        rf"(\d+) timesteps on 2 env\(s\) in {NUM} s: (\d+) steps/s, (\d+) training episodes\n"
        rf"reloaded policy gives the same (\d+) actions bit for bit: (True|False)\n"
        rf"mean return on 1 seeds: trained {NUM}, random actions {NUM}\n"
    )
    m = re.fullmatch(pattern, out)
    assert m, out
    timesteps, episodes, same = int(m[1]), int(m[4]), m[6]
    assert timesteps == 256  # 2 envs x 64 steps x 2 rollouts
    assert same == "True", out
    assert all(math.isfinite(float(v)) for v in (m[7], m[8])), out

    # the learning curve: one row per finished episode, each at most as long as the time limit
    # allows (3 s of 12-tick steps at the scenario's control rate; one more step where the
    # summed step times fall a rounding short of it)
    hz = NOVAK["time"]["control_hz"]
    max_len = math.ceil(3.0 * hz / 12) + 1
    with open(tmp_path / "run" / "learning_curve.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == episodes >= 2 * (128 // max_len)  # each env steps 128 times
    steps = [int(r["timestep"]) for r in rows]
    assert steps == sorted(steps) and 0 < steps[-1] <= timesteps
    assert all(1 <= int(r["length"]) <= max_len for r in rows), rows
    assert sum(int(r["length"]) for r in rows) <= timesteps
    assert all(math.isfinite(float(r["return"])) for r in rows), rows
    assert (tmp_path / "run" / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "run" / "ppo.zip").stat().st_size > 0

    # seeded: a second run gives the same curve and the same evaluation, bit for bit
    again = train_tiny(tmp_path, "again")
    assert again.splitlines()[1:] == out.splitlines()[1:]  # the first line holds the wall time
    curve = (tmp_path / "again" / "learning_curve.csv").read_bytes()
    assert curve == (tmp_path / "run" / "learning_curve.csv").read_bytes()


def test_train_marl_trains_one_shared_policy_and_repeats_bit_for_bit(tmp_path: Path) -> None:
    out = train_tiny(tmp_path, "run", "train_marl.py", envs=1)
    agents = len(NOVAK["vehicles"])
    pattern = (
        rf"(\d+) environment steps \((\d+) agent steps\) on 1 env\(s\) in {NUM} s: "
        rf"(\d+) steps/s, (\d+) training episodes\n"
        rf"reloaded policy gives the same (\d+) actions bit for bit: (True|False)\n"
        rf"mean team return on 1 seeds: trained {NUM}, random actions {NUM}\n"
    )
    m = re.fullmatch(pattern, out)
    assert m, out
    steps, agent_steps, episodes = int(m[1]), int(m[2]), int(m[5])
    assert (steps, agent_steps) == (256, 256 * agents)  # 64-step rollouts x 4, every agent
    assert int(m[6]) == agents + 8 and m[7] == "True", out  # each agent's first obs + 8 samples
    assert all(math.isfinite(float(v)) for v in (m[8], m[9])), out

    # one row per finished episode of the swarm: at most the 3-s limit in 12-tick steps (one
    # more where the summed step times fall a rounding short of it), plus the step in which
    # SuperSuit closes the episode after its last agent ended
    max_len = math.ceil(3.0 * NOVAK["time"]["control_hz"] / 12) + 2
    run = tmp_path / "run"
    with open(run / "learning_curve.csv") as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["step", "team_return", "length"]
    assert len(rows) == episodes >= 256 // max_len
    ends = [int(r["step"]) for r in rows]
    assert ends == sorted(ends) and 0 < ends[-1] <= steps
    # one copy: the episodes tile the run, each ending where the previous one's length says
    assert ends == list(np.cumsum([int(r["length"]) for r in rows]))
    assert all(2 <= int(r["length"]) <= max_len for r in rows), rows
    assert all(math.isfinite(float(r["team_return"])) for r in rows), rows
    assert (run / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # seeded: a second run gives the same curve, figure, weights and evaluation, bit for bit
    # (not the same zip: SB3 stores the policy class's repr, memory addresses included)
    again = train_tiny(tmp_path, "again", "train_marl.py", envs=1)
    assert again.splitlines()[1:] == out.splitlines()[1:]  # the first line holds the wall time
    for name in ("learning_curve.csv", "learning_curve.png"):
        assert (tmp_path / "again" / name).read_bytes() == (run / name).read_bytes(), name
    weights = []
    for d in (run, tmp_path / "again"):
        with zipfile.ZipFile(d / "ppo_shared.zip") as z:
            weights.append([z.read(n) for n in ("policy.pth", "policy.optimizer.pth")])
    assert weights[0] == weights[1]
