"""Train one PPO policy (Stable-Baselines3) shared by every agent of the PettingZoo environment.

Parameter sharing, PettingZoo's documented recipe for SB3: every agent of every copy of
plumeswarm_v0.parallel_env is a slot of one vector environment (SuperSuit), and one policy acts
for all of them from each agent's own observation. Needs the `train` extra (as train_sb3.py):

    pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu
    pip install 'plumeswarm[train]'
    python examples/train_marl.py --envs 1 --steps 12288 --seed 0 --episodes 10 --out runs/marl

`--envs N` runs N copies of the environment, each in its own worker process (one copy steps
in-process), copy i seeded with seed + i; `--steps` counts environment steps (one step moves
every vehicle of a copy), all copies together. Every finished training episode is a row of
OUT/learning_curve.csv (step, team return: the sum of every agent's rewards, length), plotted in
OUT/learning_curve.png beside the mean team return of random actions on the evaluation seeds.
The policy is saved to OUT/ppo_shared.zip, loaded back, checked to give the same actions bit for
bit, then evaluated with the random policy on the same seeds. Numbers: docs/envs.md.
"""

import time

import numpy as np
from _training import parse_args, write_curve
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback

from plumeswarm.envs.pettingzoo import plumeswarm_v0
from plumeswarm.envs.shared_policy import agents_vec_env

args = parse_args(__doc__, "environment steps, all copies", "runs/train_marl")
env_kwargs = {"scenario_overrides": args.set}


class TeamCurve(BaseCallback):
    """Every finished episode of every copy: environment step, team return, length.

    Slot c * A + a is agent a of copy c; the agents of a copy end their episode together (an
    agent that ended before the others waits, observing zeros, earning 0)."""

    def __init__(self, agents: int) -> None:
        super().__init__()
        self.agents = agents
        self.rows: list[tuple[int, float, int]] = []

    def _on_training_start(self) -> None:
        copies = self.training_env.num_envs // self.agents
        self.team = np.zeros(copies)
        self.length = np.zeros(copies, dtype=int)

    def _on_step(self) -> bool:
        rewards = self.locals["rewards"].reshape(-1, self.agents)
        ended = self.locals["dones"].reshape(-1, self.agents).all(axis=1)
        self.team += rewards.sum(axis=1, dtype=np.float64)
        self.length += 1
        for c in np.flatnonzero(ended):
            step = self.num_timesteps // self.agents
            self.rows.append((step, float(self.team[c]), int(self.length[c])))
            self.team[c], self.length[c] = 0.0, 0
        return True


def evaluate(env, act, seeds) -> float:
    """The mean team return over one episode per seed; act(agent, observation) -> action."""
    returns = []
    for seed in seeds:
        observations, _ = env.reset(seed=seed)
        total = 0.0
        while env.agents:
            actions = {agent: act(agent, observations[agent]) for agent in env.agents}
            observations, rewards, _, _, _ = env.step(actions)
            total += sum(rewards.values())
        returns.append(total)
    return float(np.mean(returns))


if __name__ == "__main__":  # the worker processes import this file
    env = plumeswarm_v0.parallel_env(**env_kwargs)
    agents = len(env.possible_agents)
    venv = agents_vec_env(args.envs, args.seed, **env_kwargs)
    model = PPO(
        "MlpPolicy",
        venv,
        n_steps=args.n_steps,
        batch_size=min(64 * agents, args.n_steps * venv.num_envs),
        seed=args.seed,
        verbose=0,
    )
    curve = TeamCurve(agents)
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.steps * agents, callback=curve)
    wall_s = time.perf_counter() - t0
    venv.close()
    env_steps = model.num_timesteps // agents

    model.save(args.out / "ppo_shared.zip")
    loaded = PPO.load(args.out / "ppo_shared.zip", device="cpu")
    seeds = range(10_000 + args.seed, 10_000 + args.seed + args.episodes)
    space = env.observation_space(env.possible_agents[0])
    probe: list[np.ndarray] = [o for s in seeds for o in env.reset(seed=s)[0].values()]
    probe += [space.sample() for _ in range(8)]
    before = np.stack([model.predict(o, deterministic=True)[0] for o in probe])
    after = np.stack([loaded.predict(o, deterministic=True)[0] for o in probe])
    same = before.tobytes() == after.tobytes()

    trained = evaluate(env, lambda agent, obs: loaded.predict(obs, deterministic=True)[0], seeds)
    rng = np.random.default_rng(args.seed)
    act_space = env.action_space(env.possible_agents[0])
    random = evaluate(
        env,
        lambda agent, obs: rng.uniform(act_space.low, act_space.high).astype(act_space.dtype),
        seeds,
    )
    env.close()

    write_curve(
        args.out,
        ["step", "team_return", "length"],
        curve.rows,
        random,
        trained,
        args.episodes,
        {
            "xlabel": "environment step",
            "ylabel": "team return",
            "title": f"shared-policy PPO, {agents} agents, {args.envs} env(s)",
        },
    )

    print(
        f"{env_steps} environment steps ({model.num_timesteps} agent steps) on {args.envs} "
        f"env(s) in {wall_s:.1f} s: {env_steps / wall_s:.0f} steps/s, "
        f"{len(curve.rows)} training episodes"
    )
    print(f"reloaded policy gives the same {len(probe)} actions bit for bit: {same}")
    print(
        f"mean team return on {args.episodes} seeds: trained {trained:.2f}, "
        f"random actions {random:.2f}"
    )
