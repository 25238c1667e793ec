"""Train PPO (Stable-Baselines3) on plumeswarm/PlumeSource-v0 over N parallel environments.

Needs the `train` extra (Stable-Baselines3 and PyTorch 2.13.0, about 0.9 GB; the CPU build
first, or pip may take PyPI's multi-GB CUDA one):

    pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu
    pip install 'plumeswarm[train]'
    python examples/train_sb3.py --envs 1 --steps 32768 --seed 0 --episodes 10 --out runs/train

`--envs N` runs N copies of the environment, each in its own process (SB3's SubprocVecEnv; one
copy runs in-process), copy i seeded with seed + i. Every finished training episode is a row of
OUT/learning_curve.csv (timestep, return, length), plotted in OUT/learning_curve.png beside the
mean return of random actions on the evaluation seeds. The policy is saved to OUT/ppo.zip,
loaded back, checked to give the same actions bit for bit, then evaluated with the random
policy on the same seeds. Throughput and the full run's numbers: docs/envs.md.
"""

import time

import gymnasium
import numpy as np
from _training import parse_args, write_curve
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

ENV_ID = "plumeswarm.envs:plumeswarm/PlumeSource-v0"

args = parse_args(__doc__, "training timesteps, all envs", "runs/train_sb3")
env_kwargs = {"scenario_overrides": args.set}


class Curve(BaseCallback):
    """Every finished episode (from the Monitor wrapper's info): timestep, return, length."""

    def __init__(self) -> None:
        super().__init__()
        self.rows: list[tuple[int, float, int]] = []

    def _on_step(self) -> bool:
        for info in self.locals["infos"]:
            if "episode" in info:
                self.rows.append((self.num_timesteps, info["episode"]["r"], info["episode"]["l"]))
        return True


def evaluate(env, policy, seeds) -> float:
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


if __name__ == "__main__":  # SubprocVecEnv's workers import this file
    vec_cls = SubprocVecEnv if args.envs > 1 else DummyVecEnv
    venv = make_vec_env(
        ENV_ID, n_envs=args.envs, seed=args.seed, vec_env_cls=vec_cls, env_kwargs=env_kwargs
    )
    batch = min(64, args.n_steps * args.envs)
    model = PPO(
        "MlpPolicy", venv, n_steps=args.n_steps, batch_size=batch, seed=args.seed, verbose=0
    )
    curve = Curve()
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.steps, callback=curve)
    wall_s = time.perf_counter() - t0
    venv.close()

    model.save(args.out / "ppo.zip")
    loaded = PPO.load(args.out / "ppo.zip", device="cpu")
    env = gymnasium.make(ENV_ID, **env_kwargs)
    seeds = range(10_000 + args.seed, 10_000 + args.seed + args.episodes)
    probe = [env.reset(seed=s)[0] for s in seeds] + [
        env.observation_space.sample() for _ in range(8)
    ]
    before = np.stack([model.predict(o, deterministic=True)[0] for o in probe])
    after = np.stack([loaded.predict(o, deterministic=True)[0] for o in probe])
    same = before.tobytes() == after.tobytes()

    trained = evaluate(env, lambda obs: loaded.predict(obs, deterministic=True)[0], seeds)
    rng = np.random.default_rng(args.seed)
    space = env.action_space
    assert isinstance(space, gymnasium.spaces.Box)
    random = evaluate(
        env, lambda obs: rng.uniform(space.low, space.high, space.shape).astype(space.dtype), seeds
    )
    env.close()

    write_curve(
        args.out,
        ["timestep", "return", "length"],
        curve.rows,
        random,
        trained,
        args.episodes,
        {"xlabel": "timestep", "ylabel": "episode return", "title": f"PPO, {args.envs} env(s)"},
    )

    print(
        f"{model.num_timesteps} timesteps on {args.envs} env(s) in {wall_s:.1f} s: "
        f"{model.num_timesteps / wall_s:.0f} steps/s, {len(curve.rows)} training episodes"
    )
    print(f"reloaded policy gives the same {len(probe)} actions bit for bit: {same}")
    print(
        f"mean return on {args.episodes} seeds: trained {trained:.2f}, random actions {random:.2f}"
    )
