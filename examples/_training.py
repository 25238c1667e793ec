"""What the two training examples (train_sb3.py, train_marl.py) share: their options and their
learning-curve outputs (a CSV, one row per finished training episode, and its plot)."""

import argparse
import csv
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np


def parse_args(doc: str, steps_help: str, out: str) -> argparse.Namespace:
    """--envs, --steps, --seed, --episodes, --n-steps, --out, --set; OUT is created."""
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    parser.add_argument("--envs", type=int, default=1, help="parallel environments (processes)")
    parser.add_argument("--steps", type=int, default=2048, help=steps_help)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=int, default=3, help="evaluation episodes")
    parser.add_argument("--n-steps", type=int, default=256, help="PPO rollout length per env")
    parser.add_argument("--out", type=Path, default=Path(out))
    parser.add_argument(
        "--set", action="append", default=[], metavar="KEY=VALUE", help="scenario override"
    )
    args = parser.parse_args()
    if args.envs < 1 or args.steps < 1 or args.n_steps < 2:
        parser.error(
            f"--envs {args.envs}, --steps {args.steps}, --n-steps {args.n_steps}: too small"
        )
    args.out.mkdir(parents=True, exist_ok=True)
    return args


def write_curve(
    out: Path,
    header: list[str],
    rows: list[tuple[int, float, int]],
    random: float,
    trained: float,
    episodes: int,
    labels: dict[str, str],
) -> None:
    """OUT/learning_curve.csv (header, then step, return, length per episode) and
    OUT/learning_curve.png: the episodes, their running mean and the two evaluation means;
    ``labels`` holds the plot's xlabel, ylabel and title."""
    with open(out / "learning_curve.csv", "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(header)
        writer.writerows((t, f"{r:.6f}", n) for t, r, n in rows)
    fig, ax = plt.subplots(figsize=(7, 4))
    if rows:
        t, r = np.array([row[0] for row in rows]), np.array([row[1] for row in rows])
        ax.plot(t, r, ".", alpha=0.3, label="training episode")
        k = max(1, len(r) // 20)
        ax.plot(t[k - 1 :], np.convolve(r, np.ones(k) / k, "valid"), label=f"mean of {k}")
    ax.axhline(random, color="grey", ls="--", label=f"random actions, {episodes} eval seeds")
    ax.axhline(trained, color="C3", ls=":", label=f"trained policy, {episodes} eval seeds")
    ax.set(**labels)
    ax.legend(loc="lower right")
    fig.tight_layout()
    fig.savefig(out / "learning_curve.png", dpi=80)
