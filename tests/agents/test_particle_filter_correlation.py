"""The particle filter's correlated windows: the effective sample size against closed forms, and
the tempered filter's credible region against the truth it was drawn from."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.behavior import BehaviorContext
from agents.behaviors.particle_filter import (
    FloatArray,
    ParticleFilter,
    SourceTermFilter,
    WindowMean,
    effective_fraction,
    mass_within,
)
from agents.behaviors.wind import WindFrame
from plume_atmosphere.dispersion import dispersion_curves
from plumeswarm.gsl.registry import BUILTIN_ALGORITHMS, tuned_behavior
from plumeswarm.gsl.tuned import __getattr__ as tuned_class
from swarmbus.errors import PlumeswarmError
from swarmbus.scenario import load_scenario


def ar1(phi: float, n: int, rng: np.random.Generator) -> FloatArray:
    """x_t = φ x_{t−1} + e_t, started in its stationary distribution."""
    e = rng.normal(size=n)
    x = np.empty(n)
    x[0] = e[0] / math.sqrt(1.0 - phi**2)
    for t in range(1, n):
        x[t] = phi * x[t - 1] + e[t]
    return x


@pytest.mark.parametrize("phi", [0.0, 0.5, math.exp(-1.0 / 7.38)])
def test_the_effective_fraction_of_an_ar1_series_is_its_closed_form(phi: float) -> None:
    """n_eff / n of an AR(1) series is (1 − φ) / (1 + φ) (τ = 1 + 2 Σ φᵏ); φ = e^(−1/7.38) is a
    1 s window in an Ornstein–Uhlenbeck meander of 7.38 s: 0.068. The mean of 20 series of
    3000 samples within 10 % (its standard error is 2–4 % at these φ)."""
    rng = np.random.default_rng(5)
    fractions = [effective_fraction(ar1(phi, 3000, rng)) for _ in range(20)]
    expected = (1.0 - phi) / (1.0 + phi)
    assert np.mean(fractions) == pytest.approx(expected, rel=0.1)


@pytest.mark.parametrize("block", [2, 5, 8])
def test_a_series_of_repeated_values_counts_each_value_once(block: int) -> None:
    """Independent values each repeated ``block`` times: ρ(k) = 1 − k / block, so τ = block and
    n_eff / n = 1 / block. Two such components pooled give the same."""
    rng = np.random.default_rng(block)
    values = np.repeat(rng.normal(size=(400, 2)), block, axis=0)
    assert effective_fraction(values[:, 0]) == pytest.approx(1.0 / block, rel=0.15)
    assert effective_fraction(values) == pytest.approx(1.0 / block, rel=0.15)


def test_the_effective_fraction_is_one_for_short_or_constant_series() -> None:
    assert effective_fraction([1.0, 2.0, 3.0]) == 1.0
    assert effective_fraction(np.full(50, 4.0)) == 1.0
    assert effective_fraction(np.zeros((50, 2))) == 1.0


def test_the_mass_within_a_radius_is_the_weight_of_the_particles_there() -> None:
    particles = np.array([[0.0, 0.0, 1.0], [1.5, 0.0, 1.0], [0.0, 2.5, 1.0], [3.0, 3.0, 1.0]])
    weights = np.array([0.4, 0.3, 0.2, 0.1])
    assert mass_within(particles, weights, 0.0, 0.0, 2.0) == pytest.approx(0.7)
    assert mass_within(particles, weights, 0.0, 0.0, 2.5) == pytest.approx(0.9)


WIND = (5.0, 0.0)
CURVES = dispersion_curves("mcmullen", "D")


def region_covers_the_truth(seed: int, effective: bool, repeats: int = 5) -> bool:
    """One source drawn from the filter's prior (2000 particles, as the behaviour's; with 1000
    the particle approximation itself covers less); windows at 38 hover points 15 and 25 m
    downwind, each point's reading drawn from the filter's own observation model (detection
    with P(detection | c), a log-normal magnitude) once and repeated ``repeats`` windows (as
    readings in one meander are). Is the truth in the disc about the estimate holding 90 % of
    the weight? With the windows weighted by n_eff / n of the draws' series the posterior is
    that of the distinct readings, so the region covers the truth in 90 % of the draws."""
    rng = np.random.default_rng(seed)

    def prior(n: int) -> FloatArray:
        q = np.exp(rng.uniform(math.log(0.5), math.log(50.0), n))
        return np.column_stack([rng.uniform(-10.0, 10.0, n), rng.uniform(-5.0, 5.0, n), q])

    truth = SourceTermFilter(prior(1), CURVES, 10.0, rng)
    pf = SourceTermFilter(prior(2000), CURVES, 10.0, rng)
    draws: list[tuple[float, float]] = []
    for x in (15.0, 25.0):
        for y in np.arange(-9.0, 9.5, 1.0):
            c = truth.predict(x, float(y), 10.0, WIND)
            u, z = float(rng.random()), float(rng.normal())
            detected = u < float(truth.detection_probability(c)[0])
            eps = pf.floor_g_m3
            value = math.exp(math.log(float(c[0]) + eps) + pf.log_sigma * z) - eps
            for _ in range(repeats):
                draws.append((u, z))
                if effective:
                    pf.tempering = effective_fraction(draws)
                pf.update_mean([(x, float(y), 10.0)], value if detected else 0.0, WIND, detected)
    mx, my, _, _ = pf.estimate()
    distance = np.hypot(pf.particles[:, 0] - mx, pf.particles[:, 1] - my)
    order = np.argsort(distance)
    radius = distance[order][np.searchsorted(np.cumsum(pf.weights[order]), 0.9)]
    x0, y0 = truth.particles[0, :2]
    return bool(math.hypot(x0 - mx, y0 - my) <= radius)


def binomial_interval(n: int, p: float, level: float) -> tuple[int, int]:
    """The central ``level`` interval of Binomial(n, p), by summing its probabilities."""
    pmf = [math.comb(n, k) * p**k * (1.0 - p) ** (n - k) for k in range(n + 1)]
    cdf = np.cumsum(pmf)
    tail = (1.0 - level) / 2.0
    return int(np.searchsorted(cdf, tail)), int(np.searchsorted(cdf, 1.0 - tail))


def test_the_tempered_filter_is_90_percent_sure_90_percent_of_the_time() -> None:
    """100 draws: the tempered filter's 90 % region covers the truth a number of times inside
    the 99.9 % interval of Binomial(100, 0.9) (79–98); the untempered one, counting each reading
    five times, is sure of too small a region: on 30 of the draws it covers the truth fewer
    times than the same interval of Binomial(30, 0.9) allows."""
    low, high = binomial_interval(100, 0.9, 0.999)
    tempered = sum(region_covers_the_truth(seed, effective=True) for seed in range(100))
    assert low <= tempered <= high, (tempered, low, high)
    low_30, _ = binomial_interval(30, 0.9, 0.999)
    untempered = sum(region_covers_the_truth(seed, effective=False) for seed in range(30))
    assert untempered < low_30, (untempered, low_30)


def test_an_unknown_likelihood_is_one_line_naming_the_valid_ones() -> None:
    behavior = tuned_behavior(BUILTIN_ALGORITHMS["particle_filter"].behavior, {"likelihood": "x"})
    cls = tuned_class(behavior.partition(":")[2])
    ctx = BehaviorContext("uav1", 0, load_scenario(), 0.05, np.random.default_rng(0))
    with pytest.raises(PlumeswarmError, match="likelihood: 'x': valid: independent, effective"):
        cls(ctx)
    assert issubclass(cls, ParticleFilter)


def test_the_behaviour_weighs_its_windows_by_its_own_winds_only_when_asked() -> None:
    """Windows whose mean winds are independent values each held for 5 windows (a meander
    of 5 s seen at 1 Hz): the effective filter weighs each by about 1/5; the default by 1."""
    rng = np.random.default_rng(3)
    winds = 5.0 + np.repeat(rng.normal(0.0, 0.5, size=(40, 2)), 5, axis=0)
    scenario = load_scenario()
    weights = {}
    for likelihood in ("independent", "effective"):
        cls = tuned_class(
            tuned_behavior(
                BUILTIN_ALGORITHMS["particle_filter"].behavior, {"likelihood": likelihood}
            ).partition(":")[2]
        )
        pf = cls(BehaviorContext("uav1", 0, scenario, 0.05, np.random.default_rng(0)))
        pf.filter = pf._new_filter(WindFrame.of((5.0, 0.0)), 50.0, 0.0)
        for e, n in winds:
            pf._update(0.0, WindowMean([(50.0, 0.0, 10.0)], 0.0, (float(e), float(n)), False))
        weights[likelihood] = pf.filter.tempering
    assert weights["independent"] == 1.0
    assert weights["effective"] == pytest.approx(1.0 / 5.0, rel=0.15)
