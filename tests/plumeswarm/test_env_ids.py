"""Every ``plumeswarm/...`` Gymnasium id, the PettingZoo module, and the standard wrappers.

Expected values come from the scenario files read with ``tomllib``, from the PettingZoo
environment run alongside (a second path to the same numbers), or from counting in the test.
"""

from __future__ import annotations

import json
import tomllib
from typing import Any

import gymnasium
import numpy as np
import pytest
from gymnasium.utils import seeding
from gymnasium.wrappers import FrameStackObservation, RecordEpisodeStatistics
from pettingzoo.test import api_test, parallel_api_test

from plumeswarm.envs import ENV_IDS, PlumeSourceEnv, PlumeSwarmEnv
from plumeswarm.envs.pettingzoo import plumeswarm_v0
from swarmbus.scenario import SCENARIOS_DIR, ScenarioError
from tests.support.procs import run_python

PER_AGENT = 10 + 5 * 2 + 1  # own 10, two peers of 5, time since the last reading (docs/envs.md)


def bundled(name: str) -> dict[str, object]:
    return tomllib.loads((SCENARIOS_DIR / f"{name}.toml").read_text())


def test_every_id_makes_in_a_fresh_interpreter_with_no_prior_import() -> None:
    code = (
        "import json, gymnasium\n"
        "from gymnasium.utils.env_checker import check_env\n"
        f"ids = {ENV_IDS!r}\n"
        "out = {}\n"
        "for i in ids:\n"
        "    env = gymnasium.make('plumeswarm.envs:' + i)\n"
        "    check_env(env.unwrapped, skip_render_check=True)\n"
        "    sc = env.unwrapped.swarm.scenario\n"
        "    out[i] = [env.unwrapped.spec.id, list(env.observation_space.shape),\n"
        "              sc.plume.model, sc.sensor.resolved().mox is not None, len(sc.vehicles)]\n"
        "    env.close()\n"
        "print(json.dumps(out))\n"
    )
    res = run_python(code, 300.0)
    assert res.returncode == 0, res.stderr
    got = json.loads(res.stdout.strip().splitlines()[-1])
    n = len(bundled("novak2018")["vehicles"])  # type: ignore[arg-type]
    assert got["plumeswarm/PlumeSource-v0"] == [
        "plumeswarm/PlumeSource-v0",
        [11],
        "gaussian",
        False,
        1,
    ]
    filament = bundled("filament")["plume"]["model"]  # type: ignore[index]
    assert got["plumeswarm/PlumeSourceFilament-v0"][2] == filament == "filament"
    assert got["plumeswarm/PlumeSourceMox-v0"][3] is True  # the TGS2620 transducer
    assert got["plumeswarm/PlumeSwarm-v0"][1:] == [[n * PER_AGENT], "gaussian", False, n]


def test_the_swarm_task_is_the_pettingzoo_env_concatenated_and_summed() -> None:
    seed, steps = 11, 15
    central = gymnasium.make("plumeswarm/PlumeSwarm-v0").unwrapped
    rng, _ = seeding.np_random(seed)  # the central env seeds the swarm env from its own draw
    swarm = PlumeSwarmEnv()
    try:
        obs, _ = central.reset(seed=seed)
        pz_obs, _ = swarm.reset(seed=int(rng.integers(2**63 - 1)))
        order = swarm.possible_agents
        np.testing.assert_array_equal(obs, np.concatenate([pz_obs[a] for a in order]))
        acts = np.random.default_rng(3).uniform(-1, 1, (steps, len(order) * 4)).astype(np.float32)
        for a in acts:
            obs, reward, _, _, _ = central.step(a)
            live = list(swarm.agents)
            pz_obs, pz_rew, _, _, _ = swarm.step(
                {v: a[4 * i : 4 * i + 4] for i, v in enumerate(order) if v in live}
            )
            assert reward == pytest.approx(sum(pz_rew.values()), abs=0.0)
            for i, v in enumerate(order):
                if v in pz_obs:
                    np.testing.assert_array_equal(
                        obs[i * PER_AGENT : (i + 1) * PER_AGENT], pz_obs[v]
                    )
    finally:
        central.close()
        swarm.close()


def test_scenario_overrides_reach_the_env_and_a_bad_key_is_one_line() -> None:
    env = gymnasium.make("plumeswarm/PlumeSource-v0", scenario_overrides=["wind.speed_m_s=4.5"])
    assert isinstance(env.unwrapped, PlumeSourceEnv)
    assert env.unwrapped.swarm.scenario.wind.speed_m_s == 4.5
    env.close()
    with pytest.raises(ScenarioError) as err:
        PlumeSwarmEnv(scenario_overrides=["sensor.bogus=1"])
    assert "\n" not in str(err.value) and "bogus" in str(err.value)


def test_make_vec_steps_two_copies_with_their_own_seeds() -> None:
    envs = gymnasium.make_vec("plumeswarm/PlumeSource-v0", num_envs=2, vectorization_mode="sync")
    try:
        obs, _ = envs.reset(seed=[1, 2])  # type: ignore[arg-type]  # Gymnasium takes a list
        assert obs.shape == (2, 11)
        assert not np.array_equal(obs[0], obs[1])  # different seeds, different starts
        for _ in range(3):
            obs, rew, *_ = envs.step(np.zeros((2, 4), dtype=np.float32))
        assert obs.shape == (2, 11) and rew.shape == (2,)
        one = gymnasium.make("plumeswarm/PlumeSource-v0")
        first, _ = one.reset(seed=1)
        one.close()
        envs2 = gymnasium.make_vec("plumeswarm/PlumeSource-v0", num_envs=2)
        again, _ = envs2.reset(seed=[1, 2])  # type: ignore[arg-type]
        envs2.close()
        np.testing.assert_array_equal(again[0], first)  # copy 0 with seed 1 is the env with seed 1
    finally:
        envs.close()


def test_frame_stack_and_episode_statistics() -> None:
    env = RecordEpisodeStatistics(
        FrameStackObservation(gymnasium.make("plumeswarm/PlumeSource-v0"), stack_size=4)
    )
    obs, _ = env.reset(seed=5)
    assert obs.shape == (4, 11)
    for frame in obs[:3]:  # Gymnasium pads with the reset observation by default
        np.testing.assert_array_equal(frame, obs[3])
    first = obs[3]
    steps, total, done, info = 0, 0.0, False, dict[str, Any]()
    while not done:
        obs, reward, terminated, truncated, info = env.step(np.zeros(4, dtype=np.float32))
        if steps == 0:  # the oldest frames shift out, the newest is the step's
            np.testing.assert_array_equal(obs[2], first)
        steps, total, done = steps + 1, total + float(reward), terminated or truncated
    assert info["episode"]["l"] == steps
    assert info["episode"]["r"] == pytest.approx(total, rel=1e-6)
    env.close()


def test_the_pettingzoo_module_and_its_metadata_name_are_one_name() -> None:
    """PettingZoo's convention (``pistonball_v6``): ``metadata["name"]`` is the versioned
    module's name, for the parallel and the AEC form alike."""
    module = plumeswarm_v0.__name__.rsplit(".", 1)[1]
    assert module == "plumeswarm_v0"
    assert PlumeSwarmEnv.metadata["name"] == module
    aec = plumeswarm_v0.env()
    try:
        assert aec.metadata["name"] == module
    finally:
        aec.close()


# agents are the scenario's vehicle ids, not PettingZoo's recommended <name>_<number>
@pytest.mark.filterwarnings("ignore:We recommend agents to be named")
def test_pettingzoo_module_parallel_and_aec_pass_the_api_tests() -> None:
    parallel = plumeswarm_v0.parallel_env()
    parallel_api_test(parallel, num_cycles=20)
    parallel.close()
    aec = plumeswarm_v0.env()
    api_test(aec, num_cycles=5)
    aec.close()


def test_supersuit_vectorises_the_parallel_env() -> None:
    ss = pytest.importorskip(
        "supersuit", reason="SuperSuit is not installed (pip install supersuit)"
    )
    venv = ss.pettingzoo_env_to_vec_env_v1(plumeswarm_v0.parallel_env())
    try:
        obs, _ = venv.reset(seed=0)
        n = len(bundled("novak2018")["vehicles"])  # type: ignore[arg-type]
        assert np.asarray(obs).shape == (n, PER_AGENT)
        obs, rew, *_ = venv.step(np.zeros((n, 4), dtype=np.float32))
        assert np.asarray(rew).shape == (n,)
    finally:
        venv.close()
