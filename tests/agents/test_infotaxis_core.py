"""The infotaxis core against independent maths: scipy's Poisson law, Bayes' rule and the
expected entropy worked by hand, OTTO's printed parameters, and the encounter model's
definition."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import k0
from scipy.stats import poisson

from agents.behaviors.infotaxis_core import (
    PlumeEncounterModel,
    PlumeHitStatistics,
    SparseLikelihoods,
    bayes_update,
    choose_move,
    entropy_bits,
    expected_entropy,
    expected_entropy_sparse,
    hit_likelihoods,
    hit_statistics_from_points,
    isotropic_mean_hits,
    model_from_statistics,
    mu0_poisson,
    poisson_classes,
)


def test_poisson_classes_are_scipys_law_with_the_tail_in_the_last_class() -> None:
    mu = np.array([0.0, 0.05, 0.6, 2.5, 7.0])
    got = poisson_classes(mu, 4)
    for h in range(3):
        np.testing.assert_allclose(got[h], poisson.pmf(h, mu), rtol=1e-12, atol=1e-300)
    np.testing.assert_allclose(got[3], poisson.sf(2, mu), rtol=1e-9, atol=1e-15)


def test_the_miss_floor_raises_p0_and_keeps_the_ratios_of_the_other_classes() -> None:
    mu = np.array([0.1, 2.0, 5.0])
    plain = poisson_classes(mu, 4)
    floored = hit_likelihoods(mu, 4, miss_floor=0.25)
    np.testing.assert_allclose(floored.sum(axis=0), 1.0, rtol=1e-12)
    # e^-0.1 = 0.905 > 0.25: untouched; e^-2 = 0.135 and e^-5 = 0.0067: raised to 0.25
    np.testing.assert_allclose(floored[:, 0], plain[:, 0], rtol=1e-12)
    np.testing.assert_allclose(floored[0, 1:], 0.25)
    for k in (1, 2):
        np.testing.assert_allclose(floored[1:, k] / floored[1, k], plain[1:, k] / plain[1, k])


def test_the_2d_pomdp_parameters_are_otto_s() -> None:
    """OTTO 1.0.2 (C0PEP0D/otto 1467029f) prints MU0_POISSON = 0.6074098691429316 for 2D,
    λ/Δx = 2, R·Δt = 2; Loisy & Eloy (2022) eq. 2.5: μ0 = R·Δt·K0(1)/ln(λ/a), a = Δx/2."""
    assert mu0_poisson(2, 2.0, 2.0) == pytest.approx(0.6074098691429316, rel=1e-12)
    assert mu0_poisson(2, 2.0, 2.0) == pytest.approx(2.0 * float(k0(1.0)) / math.log(4.0))
    # μ(r) = μ0 K0(r/λ)/K0(1): at r = λ it is μ0, and the source's own cell counts as r = 1
    r = np.array([0.0, 1.0, 2.0, 5.0])
    mu = isotropic_mean_hits(r, 2, 2.0, 2.0)
    assert mu[2] == pytest.approx(0.6074098691429316)
    assert mu[0] == mu[1] == pytest.approx(0.6074098691429316 * float(k0(0.5) / k0(1.0)))
    assert mu[3] == pytest.approx(0.6074098691429316 * float(k0(2.5) / k0(1.0)))


def test_bayes_update_is_bayes_rule_with_the_searchers_cell_ruled_out() -> None:
    prior = np.array([0.1, 0.2, 0.3, 0.4])
    likelihood = np.array([0.5, 0.1, 0.9, 0.2])
    here = np.array([False, False, False, True])
    # by hand: 0.05, 0.02, 0.27, 0 → /0.34
    np.testing.assert_allclose(
        bayes_update(prior, likelihood, here), [0.05 / 0.34, 0.02 / 0.34, 0.27 / 0.34, 0.0]
    )
    # nothing explains it: the prior without the searcher's cell
    np.testing.assert_allclose(
        bayes_update(prior, np.array([0.0, 0.0, 0.0, 1.0]), here), [1 / 6, 2 / 6, 3 / 6, 0.0]
    )


def test_expected_entropy_averages_the_posteriors_entropy_over_found_and_each_count() -> None:
    belief = np.array([0.5, 0.25, 0.25])
    here = np.array([True, False, False])
    # two hit classes; cells 1 and 2 give a hit with 0.8 and 0.2
    likelihoods = np.array([[0.0, 0.2, 0.8], [0.0, 0.8, 0.2]])
    # found with 0.5 (entropy 0); else cells 1, 2 at 1/2 each: P(h=0) = P(h=1) = 0.5, and each
    # posterior is (0.2, 0.8) or (0.8, 0.2), entropy H(0.2) bits
    h02 = -(0.2 * math.log2(0.2) + 0.8 * math.log2(0.8))
    assert expected_entropy(belief, likelihoods, here) == pytest.approx(0.5 * h02)
    assert entropy_bits(belief) == pytest.approx(1.5)


def test_nuisance_axes_are_summed_out_before_the_entropy() -> None:
    """Two models × two cells; the entropy is of the source's place only."""
    belief = np.array([[0.25, 0.25], [0.25, 0.25]])
    # model 0 says cell 0 gives hits, model 1 says cell 1 does: a hit says nothing of the place
    likelihoods = np.array([[[0.0, 1.0], [1.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]]])
    assert expected_entropy(belief, likelihoods, None, nuisance_axes=1) == pytest.approx(1.0)
    # both models say cell 1 gives hits: a count tells the place (0 bits left) but not the
    # model (1 bit left of the joint)
    same = np.array([[[1.0, 0.0], [1.0, 0.0]], [[0.0, 1.0], [0.0, 1.0]]])
    assert expected_entropy(belief, same, None, nuisance_axes=1) == pytest.approx(0.0)
    assert expected_entropy(belief, same, None) == pytest.approx(1.0)


def test_choose_move_takes_the_first_of_the_lowest() -> None:
    assert choose_move([3.0, 1.0, 1.0 + 1e-12, 2.0]) == 1
    assert choose_move([2.0, 0.5]) == 1


def test_the_plume_model_is_its_definition() -> None:
    m = PlumeEncounterModel(
        axis_rate_hz=1.4,
        axis_ref_m=30.0,
        axis_decay=0.5,
        width_slope=0.08,
        width_min_m=1.0,
        background_hz=0.02,
    )
    along = np.array([30.0, 50.0, 50.0, -5.0, 5.0, 80.0])
    across = np.array([0.0, 4.0, 0.0, 0.0, 0.5, 6.4 * 7])
    got = m.rate_hz(along, across)
    assert got[0] == pytest.approx(1.4 + 0.02)
    axis50 = 1.4 * (50 / 30) ** -0.5
    assert got[2] == pytest.approx(axis50 + 0.02)
    assert got[1] == pytest.approx(axis50 * math.exp(-0.5 * (4.0 / 4.0) ** 2) + 0.02)
    assert got[3] == pytest.approx(0.02)  # upwind of the source: background only
    # 5 m downwind the width 0.4 m is below the floor of 1 m
    assert got[4] == pytest.approx(1.4 * (5 / 30) ** -0.5 * math.exp(-0.125) + 0.02)
    assert got[5] == pytest.approx(0.02)  # 7 widths across: beyond the plume's support
    assert m.mean_hits(along, across, 2.0)[0] == pytest.approx(2 * 1.42)
    near = PlumeEncounterModel(1.0, 30.0, 0.0, 0.08, 1.0, 0.0, near_source_m=10.0)
    got = near.rate_hz(np.array([0.5, 2.0, 10.0, 40.0]), np.zeros(4))
    # 10 m / along, along floored at the 1 m width floor; 1 from 10 m on
    np.testing.assert_allclose(got, [10.0, 5.0, 1.0, 1.0])


def test_a_model_from_statistics_reproduces_them() -> None:
    stats = PlumeHitStatistics(
        distances_m=(30.0, 50.0, 80.0), axis_p_hit_1s=(0.75, 0.6, 0.45), width_m=(2.4, 4.0, 6.3)
    )
    m = model_from_statistics(stats, width_min_m=1.0, background_hz=0.0)
    p1 = -np.expm1(-m.rate_hz(np.array(stats.distances_m), np.zeros(3)))
    np.testing.assert_allclose(p1, stats.axis_p_hit_1s, atol=0.03)  # a power law through 3
    assert m.width_slope == pytest.approx(
        (30 * 2.4 + 50 * 4.0 + 80 * 6.3) / (30**2 + 50**2 + 80**2)
    )


def test_statistics_from_measured_points_recover_a_gaussian_rate_profile() -> None:
    """P(hit within 1 s) = 1 − exp(−r0·exp(−y²/2w²)) sampled every 0.5 m to 6w: the axis
    value is P at y = 0 and the width w (trapezoids: within 1 %)."""
    points = []
    for x, r0, w in ((30.0, 1.2, 2.4), (50.0, 0.9, 4.0)):
        for y in np.arange(0.0, 6 * w, 0.5):
            points.append((x, float(y), 1.0 - math.exp(-r0 * math.exp(-0.5 * (y / w) ** 2))))
            points.append((x, -float(y), 1.0 - math.exp(-r0 * math.exp(-0.5 * (y / w) ** 2))))
    stats = hit_statistics_from_points(points)
    assert stats.distances_m == (30.0, 50.0)
    np.testing.assert_allclose(stats.axis_p_hit_1s, [1 - math.exp(-1.2), 1 - math.exp(-0.9)])
    np.testing.assert_allclose(stats.width_m, [2.4, 4.0], rtol=0.01)


def _models() -> list[PlumeEncounterModel]:
    return [
        PlumeEncounterModel(rate, 1.0, 0.0, factor * 0.08, 1.0, 0.02, near_source_m=10.0)
        for rate in (0.3, 1.0, 3.0)
        for factor in (0.3, 1.0)
    ]


def test_mean_hits_on_the_plume_cells_are_mean_hits_there_bit_for_bit() -> None:
    rng = np.random.default_rng(3)
    along, across = rng.uniform(-20.0, 120.0, 5000), rng.uniform(-40.0, 40.0, 5000)
    decaying = PlumeEncounterModel(1.4, 30.0, 0.5, 0.08, 1.0, 0.02, near_source_m=10.0)
    shared: dict[tuple[float, float], dict[tuple[object, ...], np.ndarray]] = {}
    for m in [*_models(), decaying, *_models()]:
        inside = m.plume_cells(along, across)
        assert 100 < inside.sum() < 5000
        want = m.mean_hits(along, across, 1.3)[inside].tobytes()
        assert m.plume_mean_hits(along[inside], across[inside], 1.3).tobytes() == want
        # the models of one width computing at the same points share their arrays
        memo = shared.setdefault((m.width_slope, m.width_min_m), {})
        assert m.plume_mean_hits(along[inside], across[inside], 1.3, memo).tobytes() == want


def _sparse(
    models: list[PlumeEncounterModel], along: np.ndarray, across: np.ndarray, dt: float
) -> tuple[SparseLikelihoods, np.ndarray]:
    """The sparse table of ``models`` at cells (along, across), and the dense one built the
    plain way: every model's classes at every cell."""
    inside = tuple(np.flatnonzero(m.plume_cells(along, across)) for m in models)
    means = [m.mean_hits(along[i], across[i], dt) for m, i in zip(models, inside, strict=True)]
    offsets = np.cumsum([0, *(len(i) for i in inside)])
    sparse = SparseLikelihoods(
        background=hit_likelihoods(np.array([0.02 * dt]), 4, 0.25)[:, 0],
        inside=inside,
        classes=hit_likelihoods(np.concatenate(means), 4, 0.25),
        offsets=tuple(int(o) for o in offsets),
        cells=len(along),
    )
    dense = np.stack([hit_likelihoods(m.mean_hits(along, across, dt), 4, 0.25) for m in models], 1)
    return sparse, dense


@pytest.mark.parametrize("cells", [1, 2, 7, 500, 4000])
@pytest.mark.parametrize("n_models", [1, 6, 9])
def test_sparse_expected_entropy_is_the_dense_one_bit_for_bit(cells: int, n_models: int) -> None:
    rng = np.random.default_rng(cells * 10 + n_models)
    models = (_models() * 2)[:n_models]
    along, across = rng.uniform(-5.0, 60.0, cells), rng.uniform(-8.0, 8.0, cells)
    sparse, dense = _sparse(models, along, across, 1.2)
    assert np.array_equal(sparse.dense(), dense)
    belief = rng.random((n_models, cells)) ** 8  # mass spread over decades
    belief /= belief.sum()
    here = np.zeros(cells, dtype=bool)
    here[rng.integers(cells)] = True
    for mask in (None, here, np.broadcast_to(here, belief.shape)):
        want = expected_entropy(belief, dense, mask, nuisance_axes=1)
        assert expected_entropy_sparse(belief, sparse, mask) == want


def test_the_concentration_likelihood_is_the_zero_inflated_gamma_law_with_strays() -> None:
    """P(class | c̄) against scipy's gamma law: with probability p a stray reading
    (exponential, mean the threshold), else 0 with probability 1 − γ and gamma(k, mean c̄/γ)
    with probability γ; the classes are the step mean's bins [0, t), [t, t·f), …, [t·f^(n−2),
    ∞)."""
    from scipy.stats import expon
    from scipy.stats import gamma as gamma_law

    from agents.behaviors.infotaxis_core import (
        concentration_class,
        concentration_edges,
        concentration_likelihoods,
    )

    t, f, n, p = 1e-3, math.sqrt(10.0), 7, 0.02
    edges = concentration_edges(t, f, n)
    np.testing.assert_allclose(edges, [t * f**j for j in range(n - 1)])
    bounds = [0.0, *edges, math.inf]
    mean = np.array([0.0, 2e-4, 3e-3, 0.05, 2.0])
    for intermittency, shape in ((1.0, 4), (0.5, 1), (0.2, 2)):
        got = concentration_likelihoods(mean, intermittency, shape, edges, p)
        assert got.shape == (n, mean.size)
        np.testing.assert_allclose(got.sum(axis=0), 1.0, rtol=1e-12)
        for i, c in enumerate(mean):
            for j in range(n):
                lo, hi = bounds[j], bounds[j + 1]
                stray = expon.cdf(hi, scale=t) - expon.cdf(lo, scale=t)
                if c > 0.0:
                    law = gamma_law(shape, scale=c / intermittency / shape)
                    plume = intermittency * (law.cdf(hi) - law.cdf(lo))
                    plume += (1.0 - intermittency) * (j == 0)  # the blanks read 0
                else:  # no plume: the reading is 0
                    plume = float(j == 0)
                want = (1.0 - p) * plume + p * stray
                assert got[j, i] == pytest.approx(want, rel=1e-9, abs=1e-15), (c, j)
    # the classes a mean reading falls in: below the threshold, each bin, beyond the last edge
    assert [concentration_class(v, t, f, n) for v in (0.0, 9.9e-4, 1e-3, 3.2e-3, 0.9)] == [
        0,
        0,
        1,
        2,
        6,
    ]


def test_the_unit_plume_is_the_gaussian_plume_released_at_the_searchers_height() -> None:
    """unit_plume_g_m3 is plume_formula's Gaussian plume of 1 g/s released at the height
    the searcher flies (its second, independent implementation of the same equation)."""
    from agents.behaviors.infotaxis_core import unit_plume_g_m3
    from plume_atmosphere.dispersion import dispersion_curves
    from plume_atmosphere.plume_formula import gaussian_plume_g_m3

    curves = dispersion_curves("mcmullen", "C")
    along = np.array([3.0, 10.0, 40.0, 90.0])
    across = np.array([0.0, 1.5, -6.0, 12.0])
    sy, sz = curves.sigmas(along)
    want = gaussian_plume_g_m3(along, across, 10.0, 1.0, 4.0, 10.0, curves)
    np.testing.assert_allclose(unit_plume_g_m3(along, across, 10.0, 4.0, sy, sz), want, rtol=1e-12)
