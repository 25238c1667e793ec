"""The statistics of ``plumeswarm bench gsl``: rates with Wilson intervals, one row per cell,
McNemar's exact test between two algorithms on the same starts, and a swarm's speed-up over
one vehicle with a bootstrap interval."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.stats import binomtest, bootstrap

from plumeswarm.gsl.episode import RADII_M, SUCCESS_RADIUS_M, Outcome

Z_95 = 1.959963984540054


def wilson_interval(successes: int, runs: int, z: float = Z_95) -> tuple[float, float]:
    """Wilson score interval for a binomial proportion (Wilson 1927, JASA 22:209)."""
    if runs == 0:
        return 0.0, 1.0
    p = successes / runs
    denom = 1.0 + z * z / runs
    centre = (p + z * z / (2 * runs)) / denom
    half = z * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


def mcnemar_exact(a: Sequence[bool], b: Sequence[bool]) -> tuple[int, int, float]:
    """McNemar's exact test on paired outcomes: (runs only ``a`` won, runs only ``b`` won,
    two-sided p) — the binomial test of the discordant pairs against ½ (p = 1 without any)."""
    if len(a) != len(b):
        raise ValueError(f"paired outcomes of unequal length: {len(a)} and {len(b)}")
    only_a = sum(1 for x, y in zip(a, b, strict=True) if x and not y)
    only_b = sum(1 for x, y in zip(a, b, strict=True) if y and not x)
    if only_a + only_b == 0:
        return 0, 0, 1.0
    return only_a, only_b, float(binomtest(only_a, only_a + only_b, 0.5).pvalue)


#: Bootstrap resamples of the speed-up interval, and the generator's seed (the same bytes
#: for the same runs).
BOOTSTRAP_RESAMPLES = 9999
BOOTSTRAP_SEED = 0


def speedup(
    single: Sequence[float], swarm: Sequence[float]
) -> tuple[float, tuple[float, float] | None]:
    """The speed-up median(``single``) / median(``swarm``) of paired times (run k of both: the
    same start) and its 95 % percentile bootstrap interval over the pairs
    (``scipy.stats.bootstrap``, paired resampling; None with fewer than 3 pairs)."""
    if len(single) != len(swarm) or not single:
        raise ValueError(f"paired times of lengths {len(single)} and {len(swarm)}")
    a, b = np.asarray(single, dtype=float), np.asarray(swarm, dtype=float)
    point = float(np.median(a) / np.median(b))
    if len(a) < 3:
        return point, None

    def ratio(x: np.ndarray, y: np.ndarray, axis: int = -1) -> np.ndarray:
        return np.asarray(np.median(x, axis=axis) / np.median(y, axis=axis))

    res = bootstrap(
        (a, b),
        ratio,
        paired=True,
        vectorized=True,
        n_resamples=BOOTSTRAP_RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(BOOTSTRAP_SEED),
    )
    ci = res.confidence_interval
    return point, (float(ci.low), float(ci.high))


def _r(value: float | None, digits: int = 3) -> float | None:
    return None if value is None or not math.isfinite(value) else round(float(value), digits)


def _rate(row: dict[str, Any], key: str, hits: int, n: int) -> None:
    low, high = wilson_interval(hits, n)
    row[key] = _r(hits / n)
    row[f"{key}_ci95"] = [_r(low), _r(high)]


def _within(o: Outcome, r: float) -> bool:
    return o.declared and o.final_error_m <= r


def false_declaration(o: Outcome) -> bool:
    """A declaration farther than the success radius (2 m) from the source."""
    return o.declared and o.final_error_m > SUCCESS_RADIUS_M


def summarise(outcomes: Sequence[Outcome]) -> dict[str, Any]:
    """The rates and medians of one cell's runs (the caller adds the cell's names)."""
    n = len(outcomes)
    row: dict[str, Any] = {"runs": n}
    _rate(row, "success_rate", sum(o.success for o in outcomes), n)
    row["success_ci95"] = row.pop("success_rate_ci95")
    for r in RADII_M:
        tag = f"{r:g}m"
        _rate(row, f"reached_{tag}_rate", sum(o.min_distance_m <= r for o in outcomes), n)
        _rate(row, f"declared_{tag}_rate", sum(_within(o, r) for o in outcomes), n)
    _rate(row, "false_declaration_rate", sum(false_declaration(o) for o in outcomes), n)
    row["declared_rate"] = _r(sum(o.declared for o in outcomes) / n)
    times = [o.time_to_success_s for o in outcomes if o.time_to_success_s is not None]
    q1, med, q3 = (
        (float(v) for v in np.percentile(times, [25, 50, 75])) if times else (None, None, None)
    )
    row["median_time_s"] = _r(med, 1)
    row["time_iqr_s"] = [_r(q1, 1), _r(q3, 1)]
    row["path_length_m"] = _r(float(np.median([o.path_length_m for o in outcomes])), 1)
    row["path_ratio"] = _r(
        float(np.median([o.path_length_m / o.initial_distance_m for o in outcomes])), 2
    )
    row["final_error_m"] = _r(float(np.median([o.final_error_m for o in outcomes])), 2)
    row["detections_per_min"] = _r(float(np.mean([o.detections_per_min for o in outcomes])), 1)
    return row
