"""``agents_vec_env``: every agent of N copies of the PettingZoo environment as a slot of one SB3
vector environment. Expected values come from the plain ``parallel_env`` run alongside (a second
path to the same observations) and from the scenario file (tomllib)."""

from __future__ import annotations

import math
import tomllib

import numpy as np
import pytest

from plumeswarm.envs.pettingzoo import plumeswarm_v0
from swarmbus.scenario import SCENARIOS_DIR

pytest.importorskip("supersuit", reason="the train extra is not installed")
from plumeswarm.envs.shared_policy import agents_vec_env

NOVAK = tomllib.loads((SCENARIOS_DIR / "novak2018.toml").read_text())
LIMIT = ["env.time_limit_s=0.5"]


def first_observations(seed: int) -> np.ndarray:
    env = plumeswarm_v0.parallel_env(scenario_overrides=LIMIT)
    try:
        obs, _ = env.reset(seed=seed)
        return np.stack([obs[a] for a in env.possible_agents]).astype(np.float32)
    finally:
        env.close()


def test_copies_in_worker_processes_are_seeded_and_end_their_agents_together() -> None:
    agents = len(NOVAK["vehicles"])
    venv = agents_vec_env(2, 5, scenario_overrides=LIMIT)  # two copies, two processes
    try:
        assert venv.num_envs == 2 * agents
        venv.seed(7)  # as PPO(seed=7) does: the copies take 7 and 8 at the next reset
        obs = venv.reset()
        expected = np.concatenate([first_observations(7), first_observations(8)])
        assert np.asarray(obs).tobytes() == expected.tobytes()

        # 0.5 s of 12-tick steps at the control rate; no agent reaches the source that soon,
        # and SuperSuit's black_death_v3 closes a copy's episode one step after its last agent
        limit_steps = math.ceil(0.5 * NOVAK["time"]["control_hz"] / 12)
        hold = np.zeros((venv.num_envs, 4), dtype=np.float32)
        for step in range(1, limit_steps + 2):
            _, rewards, dones, _ = venv.step(hold)
            assert rewards.shape == dones.shape == (venv.num_envs,)
            assert dones.tolist() == [step == limit_steps + 1] * venv.num_envs, step
    finally:
        venv.close()


def test_a_copy_count_below_one_is_refused_naming_it() -> None:
    with pytest.raises(ValueError, match="envs: must be >= 1, got 0"):
        agents_vec_env(0, 0)
