"""Train PPO (Stable-Baselines3) on plumeswarm/PlumeSource-v0 and compare it with random actions.

Needs the `train` extra, which CI does not install (PyTorch, about 1 GB):

    pip install 'plumeswarm[train]'
    python examples/train_sb3.py --timesteps 20000

Compute: the fused environment steps at about 300 steps/s on one core of the 2-core reference
machine (docs/envs.md, `plumeswarm bench envs`), so 20,000 timesteps take a few minutes on a CPU
(the policy's updates add about as much again); the default 2,000 is a smoke run of under a
minute that shows the loop, not a trained policy. Learning to find the source reliably needs
on the order of 10^6 timesteps.
"""

import argparse

import gymnasium
import numpy as np
from stable_baselines3 import PPO

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--timesteps", type=int, default=2000)
parser.add_argument("--episodes", type=int, default=3, help="evaluation episodes")
args = parser.parse_args()

env = gymnasium.make("plumeswarm.envs:plumeswarm/PlumeSource-v0")
model = PPO("MlpPolicy", env, n_steps=256, batch_size=64, seed=0, verbose=0)
model.learn(total_timesteps=args.timesteps)


def evaluate(policy, seeds):
    returns = []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, _ = env.step(policy(obs))
            total, done = total + float(reward), terminated or truncated
        returns.append(total)
    return float(np.mean(returns))


seeds = range(100, 100 + args.episodes)
trained = evaluate(lambda obs: model.predict(obs, deterministic=True)[0], seeds)
rng = np.random.default_rng(0)
random = evaluate(lambda obs: rng.uniform(-1, 1, 4).astype(np.float32), seeds)
print(f"after {args.timesteps} timesteps: mean return {trained:.2f} (random actions {random:.2f})")
env.close()
