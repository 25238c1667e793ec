"""How fast the two training recipes train, against the number of environment workers.

``python -m plumeswarm.bench.train [--workers 1,2] [--steps 1024] [--n-steps 128] [--out DIR]``

For each recipe and worker count W: PPO (Stable-Baselines3, seed 0) as the recipe builds it
(docs/envs.md) trains for ``steps`` environment steps on W copies of the environment, each in its
own worker process (W = 1 steps in-process):

- ``single``: ``plumeswarm/PlumeSource-v0`` (one vehicle) in SB3's ``SubprocVecEnv``, as
  examples/train_sb3.py;
- ``multi``: ``plumeswarm_v0.parallel_env`` (the scenario's vehicles, one agent each) through
  :func:`~plumeswarm.envs.shared_policy.agents_vec_env`, one policy shared by every agent, as
  examples/train_marl.py.

A row splits the wall time into the rollouts (the environments step, the policy picks the
actions) and the updates (PPO's gradient steps, on the learner alone): ``steps_per_s`` (whole
training), ``sample_steps_per_s`` (environment steps over rollout time),
``update_ms_per_step`` (update time per environment step) and ``worker_ms_per_step`` (rollout
time × W per environment step: a worker's cost of one step, what predicts W workers on W idle
cores), with the machine's ``load1`` beside them. A table on the terminal and ``DIR/train.json``.
Needs the ``train`` extra.
"""

# ruff: noqa: E402 - the extra is checked before its modules are imported

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from swarmbus.extras import require

require("python -m plumeswarm.bench.train", "stable_baselines3", "supersuit")

from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv

from plumeswarm.envs import ENV_ID
from plumeswarm.envs.shared_policy import agents_vec_env

RECIPES = ("single", "multi")


class RolloutClock(BaseCallback):
    """The wall time PPO spends collecting rollouts (the rest of ``learn`` is its updates)."""

    def __init__(self) -> None:
        super().__init__()
        self.rollout_s = 0.0
        self._start = 0.0

    def _on_rollout_start(self) -> None:
        self._start = time.perf_counter()

    def _on_rollout_end(self) -> None:
        self.rollout_s += time.perf_counter() - self._start

    def _on_step(self) -> bool:
        return True


def single_vec_env(workers: int) -> VecEnv:
    cls = SubprocVecEnv if workers > 1 else DummyVecEnv
    return make_vec_env(f"plumeswarm.envs:{ENV_ID}", n_envs=workers, seed=0, vec_env_cls=cls)


BUILDERS: dict[str, Callable[[int], VecEnv]] = {
    "single": single_vec_env,
    "multi": lambda workers: agents_vec_env(workers, 0),
}


def measure(recipe: str, workers: int, steps: int, n_steps: int) -> dict[str, Any]:
    """Train ``recipe`` on ``workers`` copies for ``steps`` environment steps; one row."""
    venv = BUILDERS[recipe](workers)
    agents = venv.num_envs // workers  # a slot per agent of each copy
    try:
        model = PPO(
            "MlpPolicy",
            venv,
            n_steps=n_steps,
            batch_size=min(64 * agents, n_steps * venv.num_envs),
            seed=0,
            verbose=0,
        )
        clock = RolloutClock()
        t0 = time.perf_counter()
        model.learn(total_timesteps=steps * agents, callback=clock)
        wall_s = time.perf_counter() - t0
    finally:
        venv.close()
    env_steps = model.num_timesteps // agents
    update_s = wall_s - clock.rollout_s
    return {
        "recipe": recipe,
        "workers": workers,
        "agents": agents,
        "env_steps": env_steps,
        "wall_s": round(wall_s, 2),
        "steps_per_s": round(env_steps / wall_s, 1),
        "agent_steps_per_s": round(env_steps * agents / wall_s, 1),
        "sample_steps_per_s": round(env_steps / clock.rollout_s, 1),
        "update_ms_per_step": round(1000 * update_s / env_steps, 2),
        "worker_ms_per_step": round(1000 * clock.rollout_s * workers / env_steps, 2),
        "load1": round(os.getloadavg()[0], 2),
    }


# (header, row key, format): the table's columns, in order
COLUMNS = [
    ("recipe", "recipe", "{}"),
    ("agents", "agents", "{}"),
    ("workers", "workers", "{}"),
    ("env steps", "env_steps", "{}"),
    ("wall s", "wall_s", "{:.1f}"),
    ("steps/s", "steps_per_s", "{:.1f}"),
    ("agent steps/s", "agent_steps_per_s", "{:.1f}"),
    ("sampling steps/s", "sample_steps_per_s", "{:.1f}"),
    ("update ms/step", "update_ms_per_step", "{:.2f}"),
    ("worker ms/step", "worker_ms_per_step", "{:.2f}"),
    ("load1", "load1", "{:.1f}"),
]


def table(rows: list[dict[str, Any]]) -> str:
    lines = ["| " + " | ".join(h for h, _, _ in COLUMNS) + " |"]
    lines.append("|---|" + "---:|" * (len(COLUMNS) - 1))
    lines += ["| " + " | ".join(f.format(r[k]) for _, k, f in COLUMNS) + " |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m plumeswarm.bench.train", description=__doc__.split("\n")[0]
    )
    p.add_argument("--workers", default="1,2", help="comma-separated worker counts")
    p.add_argument("--recipes", default=",".join(RECIPES), help="single, multi or both")
    p.add_argument("--steps", type=int, default=1024, help="environment steps per row")
    p.add_argument("--n-steps", type=int, default=128, help="PPO rollout length per copy")
    p.add_argument("--out", type=Path, default=Path("runs/bench-train"))
    a = p.parse_args(argv)
    try:
        workers = [int(v) for v in a.workers.split(",") if v.strip()]
    except ValueError:
        p.error(f"--workers {a.workers!r} is not a comma-separated list of integers")
    recipes = [r.strip() for r in a.recipes.split(",") if r.strip()]
    if unknown := [r for r in recipes if r not in RECIPES]:
        p.error(f"--recipes {','.join(unknown)}: expected single or multi")
    if not workers or min(workers) < 1 or a.steps < 1 or a.n_steps < 2:
        p.error("--workers and --steps must be positive, --n-steps at least 2")
    a.out.mkdir(parents=True, exist_ok=True)
    rows: list[dict[str, Any]] = []
    for recipe in recipes:
        for w in workers:
            print(f"{recipe}, {w} worker(s) …", flush=True)
            rows.append(measure(recipe, w, a.steps, a.n_steps))
            (a.out / "train.json").write_text(json.dumps(rows, indent=2) + "\n")
    print(table(rows))
    print(f"written: {a.out / 'train.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
