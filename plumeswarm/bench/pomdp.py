"""Infotaxis on its own model: the source-tracking POMDP of Vergassola et al. (2007) as Loisy &
Eloy (2022, Proc. R. Soc. A 478:20220118) define it and their package OTTO evaluates it.

The belief update and the move choice are :mod:`agents.behaviors.infotaxis_core`'s, the ones
the infotaxis behaviour flies with; this module only lays the POMDP around them, following
OTTO (``otto/classes/sourcetracking.py``, ``otto/evaluate/evaluate.py``):

- **Grid**: a hypercube of N cells a side, N odd, the searcher starting in the centre cell.
  N is the smallest for which, in an unbounded domain, the source lies outside the ball of
  diameter N with probability < 10⁻³ after any first hit.
- **Hits**: Poisson with mean μ(r) (:func:`~agents.behaviors.infotaxis_core.isotropic_mean_hits`,
  Euclidean distance in cells), counts capped: the last of ``n_hits`` classes is "≥ n_hits − 1",
  with ``n_hits = ⌈μ(1) + √μ(1)⌉ + 1``.
- **Start**: the source is uniform in an unbounded domain and the first observation is a hit
  (h ≥ 1): its value is drawn from P(h) ∝ Σ_r P(h | μ(r))·(shell volume at r); the prior is
  uniform over the other cells, updated by that hit.
- **Episode** ("Bayesian" evaluation, no source is drawn): each step the searcher moves one
  cell (±x, ±y, …; never off the grid), finds the source with p_end, the belief's mass in the
  cell it entered, and otherwise observes a hit count drawn from the belief's predictive
  distribution. Its arrival time T has P(T = t) = P(not found before t)·p_end(t). The
  episode ends when P(not found) < 10⁻⁶ or p_end > 1 − 10⁻¹⁰ (success); it fails at the step
  limit (2D: 500·λ/Δx/√μ₀ if μ₀ < 1, 10·N² if μ₀ < 10⁻³, 500·λ/Δx otherwise; 1D: 4N; 3D:
  the 2D rule with 5000) or when the searcher is stuck (back and forth between two cells
  nine times running), leaving P(not found) unspent.
- **Statistics**: f(T) summed over episodes; mean and standard deviation of T from f after
  dividing by its total; P(failure) = 1 − total/episodes; the 95 % interval of the mean is
  ±1.96 × (standard deviation of the per-episode means E[T]) / √episodes, as OTTO prints it.

Each episode draws its hits from its own generator, seeded by (seed, episode): the same
options give the same bits.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from agents.behaviors.infotaxis_core import (
    EPSILON,
    FloatArray,
    bayes_update,
    choose_move,
    expected_entropy,
    hit_likelihoods,
    hit_probabilities,
    isotropic_mean_hits,
    mu0_poisson,
)
from swarmbus.errors import PlumeswarmError

#: An episode succeeds once the probability of not having found the source is below this.
STOP_P = 1e-6
#: The grid holds the source with probability ≥ 1 − this after any first hit.
P_SOURCE_OUT = 1e-3
#: Back-and-forth moves in a row that count as stuck.
STUCK_REPEATS = 8


class PomdpError(PlumeswarmError, ValueError):
    """A bad option of ``plumeswarm bench pomdp``."""


@dataclass(frozen=True)
class PomdpOptions:
    dims: int = 2
    lambda_over_dx: float = 2.0
    r_dt: float = 2.0
    episodes: int = 1000
    seed: int = 0

    def __post_init__(self) -> None:
        if self.dims not in (1, 2, 3):
            raise PomdpError(f"--dims must be 1, 2 or 3, got {self.dims}")
        if not self.lambda_over_dx >= 1.0:
            raise PomdpError(f"--lambda-over-dx must be >= 1, got {self.lambda_over_dx}")
        if not self.r_dt > 0.0 or not math.isfinite(self.r_dt):
            raise PomdpError(f"--r-dt must be > 0, got {self.r_dt}")
        if self.episodes < 1:
            raise PomdpError(f"--episodes must be >= 1, got {self.episodes}")
        if self.seed < 0:
            raise PomdpError(f"--seed must be >= 0, got {self.seed}")


def _ball_volume(r: FloatArray, dims: int) -> FloatArray:
    return np.asarray((2.0 * math.gamma(1.5) * r) ** dims / math.gamma(dims / 2 + 1))


@dataclass
class Pomdp:
    """The POMDP's fixed parts for one (dims, λ/Δx, R·Δt)."""

    dims: int
    lambda_over_dx: float
    r_dt: float
    mu0: float = field(init=False)
    n_hits: int = field(init=False)
    grid: int = field(init=False)
    step_limit: int = field(init=False)
    first_hit_p: FloatArray = field(init=False)
    table: FloatArray = field(init=False)  # (n_hits, 2N+1, …): likelihoods around the centre

    def __post_init__(self) -> None:
        self.mu0 = mu0_poisson(self.dims, self.lambda_over_dx, self.r_dt)
        mu1 = float(self._mu(np.array([1.0]))[0])
        self.n_hits = math.ceil(mu1 + math.sqrt(mu1)) + 1
        radii = np.arange(1, int(1000 * self.lambda_over_dx), dtype=float)
        shells = _ball_volume(radii + 0.5, self.dims) - _ball_volume(radii - 0.5, self.dims)
        by_hit = hit_likelihoods(self._mu(radii), self.n_hits)[1:] * shells
        self.grid = max(
            2 * (int(np.argmax(1.0 - np.cumsum(p) / p.sum() < P_SOURCE_OUT)) + 1) + 1
            for p in by_hit
        )
        weights = np.concatenate([[0.0], np.maximum(0.0, by_hit.sum(axis=1))])
        self.first_hit_p = weights / weights.sum()
        self.step_limit = self._step_limit()
        n = self.grid
        axes = np.meshgrid(*([np.arange(-n, n + 1, dtype=float)] * self.dims), indexing="ij")
        dist = np.sqrt(sum(a * a for a in axes))
        self.table = hit_likelihoods(self._mu(dist), self.n_hits)
        centre: tuple[slice | int, ...] = (slice(None), *([n] * self.dims))
        self.table[centre] = 0.0  # found: no hit is observed

    def _mu(self, r: FloatArray) -> FloatArray:
        return isotropic_mean_hits(r, self.dims, self.lambda_over_dx, self.r_dt)

    def _step_limit(self) -> int:
        if self.dims == 1:
            return round(4 * self.grid)
        if self.mu0 < 1e-3:
            return int(10 * self.grid**self.dims)
        scale = 5 * 10**self.dims * self.lambda_over_dx
        return round(scale / math.sqrt(self.mu0) if self.mu0 < 1.0 else scale)

    def likelihoods_at(self, cell: tuple[int, ...]) -> FloatArray:
        """``L[h, source cell]`` for a searcher in ``cell``: the table's window."""
        n = self.grid
        window = tuple(slice(n - c, 2 * n - c) for c in cell)
        return np.asarray(self.table[(slice(None), *window)])

    def moves(self, cell: tuple[int, ...]) -> list[tuple[int, ...]]:
        """Neighbours in OTTO's action order (−x, +x, −y, +y, …), off-grid ones left out."""
        out = []
        for axis in range(self.dims):
            for step in (-1, 1):
                c = list(cell)
                c[axis] += step
                if 0 <= c[axis] < self.grid:
                    out.append(tuple(c))
        return out


@dataclass(frozen=True)
class Episode:
    arrivals: FloatArray  # P(T = t) for t = 0 … step limit
    mean_steps: float  # Σ_t P(T ≥ t): E[T] if the episode ended in success
    p_not_found: float
    failed: bool


def _mask(shape: tuple[int, ...], cell: tuple[int, ...]) -> np.ndarray:
    m = np.zeros(shape, dtype=bool)
    m[cell] = True
    return m


def run_episode(pomdp: Pomdp, rng: np.random.Generator) -> Episode:
    shape = (pomdp.grid,) * pomdp.dims
    agent = (pomdp.grid // 2,) * pomdp.dims
    first_hit = int(rng.choice(pomdp.n_hits, p=pomdp.first_hit_p))
    belief = np.full(shape, 1.0 / (pomdp.grid**pomdp.dims - 1))
    belief = bayes_update(belief, pomdp.likelihoods_at(agent)[first_hit], _mask(shape, agent))
    arrivals = np.zeros(pomdp.step_limit + 1)
    before, before2 = (0,) * pomdp.dims, (pomdp.grid,) * pomdp.dims
    repeats, t, mean_steps, p_not_found = 0, 0, 0.0, 1.0
    while True:
        options = pomdp.moves(agent)
        scores = [
            expected_entropy(belief, pomdp.likelihoods_at(c), _mask(shape, c)) for c in options
        ]
        before2, before, agent = before, agent, options[choose_move(scores)]
        repeats = repeats + 1 if before2 == agent else 0
        here = _mask(shape, agent)
        p_end = float(belief[agent])
        likelihoods = pomdp.likelihoods_at(agent)
        rest_mass = float(belief.sum() - p_end)
        t += 1
        mean_steps += p_not_found
        arrivals[t] += p_not_found * p_end
        p_not_found *= 1.0 - p_end
        if p_not_found < STOP_P or p_end > 1.0 - EPSILON or rest_mass <= EPSILON:
            return Episode(arrivals, mean_steps, p_not_found, False)
        if t > pomdp.step_limit - 1 or repeats > STUCK_REPEATS:
            return Episode(arrivals, mean_steps, p_not_found, True)
        p_h = np.maximum(0.0, hit_probabilities(belief, likelihoods, here))
        hit = int(rng.choice(pomdp.n_hits, p=p_h / p_h.sum()))
        belief = bayes_update(belief, likelihoods[hit], here)


@dataclass(frozen=True)
class PomdpResult:
    options: PomdpOptions
    grid: int
    n_hits: int
    mu0: float
    step_limit: int
    mean_arrival_steps: float
    mean_arrival_ci95: tuple[float, float]
    std_arrival_steps: float
    p_failure: float
    failed_episodes: int
    wall_s: float

    def as_json(self) -> dict[str, Any]:
        o = self.options
        return {
            "dims": o.dims,
            "lambda_over_dx": o.lambda_over_dx,
            "r_dt": o.r_dt,
            "episodes": o.episodes,
            "seed": o.seed,
            "grid": self.grid,
            "n_hits": self.n_hits,
            "mu0": self.mu0,
            "step_limit": self.step_limit,
            "mean_arrival_steps": self.mean_arrival_steps,
            "mean_arrival_ci95": list(self.mean_arrival_ci95),
            "std_arrival_steps": self.std_arrival_steps,
            "p_failure": self.p_failure,
            "failed_episodes": self.failed_episodes,
            "wall_s": self.wall_s,
        }


def summarise(
    opts: PomdpOptions, pomdp: Pomdp, episodes: list[Episode], wall_s: float
) -> PomdpResult:
    f = np.sum([e.arrivals for e in episodes], axis=0) / len(episodes)
    t = np.arange(len(f), dtype=float)
    found = float(f.sum())
    mean = float((t * f).sum() / found)
    std = math.sqrt(max(0.0, float((t * t * f).sum() / found) - mean * mean))
    per_episode = np.array([e.mean_steps for e in episodes])
    half = 1.96 * float(per_episode.std()) / math.sqrt(len(episodes))
    return PomdpResult(
        options=opts,
        grid=pomdp.grid,
        n_hits=pomdp.n_hits,
        mu0=pomdp.mu0,
        step_limit=pomdp.step_limit,
        mean_arrival_steps=mean,
        mean_arrival_ci95=(mean - half, mean + half),
        std_arrival_steps=std,
        p_failure=max(0.0, 1.0 - found),
        failed_episodes=sum(e.failed for e in episodes),
        wall_s=wall_s,
    )


def run_pomdp(
    opts: PomdpOptions, progress: Callable[[int, int], None] | None = None
) -> PomdpResult:
    """Run ``opts.episodes`` infotaxis episodes on the POMDP; ``progress(done, total)``."""
    started = time.monotonic()
    pomdp = Pomdp(opts.dims, opts.lambda_over_dx, opts.r_dt)
    seeds = np.random.SeedSequence(opts.seed).spawn(opts.episodes)
    episodes = []
    for k, ss in enumerate(seeds):
        episodes.append(run_episode(pomdp, np.random.default_rng(ss)))
        if progress is not None:
            progress(k + 1, opts.episodes)
    return summarise(opts, pomdp, episodes, time.monotonic() - started)


def report_lines(result: PomdpResult) -> list[str]:
    o = result.options
    lo, hi = result.mean_arrival_ci95
    return [
        f"infotaxis on the source-tracking POMDP: {o.dims}D, λ/Δx = {o.lambda_over_dx:g}, "
        f"R·Δt = {o.r_dt:g} (grid {result.grid}^{o.dims}, hit classes {result.n_hits}, "
        f"μ0 = {result.mu0:.4f}, step limit {result.step_limit}), seed {o.seed}",
        "| episodes | mean arrival steps (95 % CI) | std | P(failure) | failed episodes |",
        "|---|---|---|---|---|",
        f"| {o.episodes} | {result.mean_arrival_steps:.3f} ({lo:.3f}–{hi:.3f}) | "
        f"{result.std_arrival_steps:.3f} | {result.p_failure:.2e} | {result.failed_episodes} |",
        f"wall time {result.wall_s:.0f} s",
    ]


def write_result(directory: Path, result: PomdpResult) -> Path:
    directory.mkdir(parents=True, exist_ok=True)
    path = directory / "pomdp.json"
    path.write_text(json.dumps(result.as_json(), indent=2) + "\n")
    return path


def main() -> int:
    """``python -m plumeswarm.bench.pomdp``: the default setting (2D, λ/Δx = 2, R·Δt = 2), 500
    episodes."""
    result = run_pomdp(PomdpOptions(episodes=500))
    for line in report_lines(result):
        print(line)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
