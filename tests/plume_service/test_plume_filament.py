"""Filament plume (Farrell et al. 2002): mass, spread, long-time average, meander, determinism.

Expected values are closed forms: a filament carries M = Q/n; the centres spread as
√(2K·age); without meander the time average is the Gaussian
Q/(2πu s²)·exp(−y²/2s²)·[exp(−(z−H)²/2s²) + exp(−(z+H)²/2s²)], s² = R0² + (2K + γ)x/u.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from plume_atmosphere.wind import wind_model
from plume_service.field import PlumeField
from plume_service.filament import FilamentPlume, Filaments, filament_concentration
from plume_service.from_scenario import field_from_scenario
from swarmbus.scenario import PlumeFilament, Wind, WindMeander, parse_scenario

R0_2, GAMMA, K = 0.001, 0.001, 0.02


def _plume(
    rate_hz: float = 10.0,
    q: float = 1.0,
    height: float = 0.5,
    step_s: float = 0.05,
    wind: Wind | None = None,
    max_age_s: float = 120.0,
    seed: int = 1,
) -> FilamentPlume:
    params = PlumeFilament(release_rate_hz=rate_hz, step_s=step_s, max_age_s=max_age_s)
    model = wind_model(wind or Wind(speed_m_s=1.0, from_deg=270.0), seed)
    return FilamentPlume((0.0, 0.0, height), q, params, model, seed=seed)


def _half_space_integral(centre: tuple[float, float, float], radius: float, mass: float) -> float:
    """∫ C dV over z ≥ 0 of one filament (with its image), Gauss–Legendre in cylindrical
    coordinates, split where the filament's and its image's 4R balls end."""
    cx, cy, h = centre
    reach = 4.0 * radius
    nodes, weights = np.polynomial.legendre.leggauss(48)

    def gauss(a: float, b: float) -> tuple[np.ndarray, np.ndarray]:
        return 0.5 * (b - a) * nodes + 0.5 * (a + b), 0.5 * (b - a) * weights

    inner = [b for b in (reach - h, h - reach) if 0.0 < b < h + reach]
    z_breaks = sorted({0.0, h + reach, *inner})
    total = 0.0
    one = (np.array([centre]), np.array([radius]), np.array([mass]))
    for z0, z1 in itertools.pairwise(z_breaks):
        zs, wz = gauss(z0, z1)
        for z, w in zip(zs, wz, strict=True):
            rho_f = math.sqrt(max(reach**2 - (z - h) ** 2, 0.0))
            rho_i = math.sqrt(max(reach**2 - (z + h) ** 2, 0.0))
            breaks = sorted({0.0, rho_f, rho_i})
            for r0, r1 in itertools.pairwise(breaks):
                rs, wr = gauss(r0, r1)
                points = np.column_stack([cx + rs, np.full_like(rs, cy), np.full_like(rs, z)])
                values = filament_concentration(points, *one)
                total += w * float(np.sum(wr * 2.0 * math.pi * rs * values))
    return total


@pytest.mark.parametrize(
    "centre", [(0.0, 0.0, 5.0), (3.0, -2.0, 0.3), (1.0, 1.0, 0.0)], ids=["aloft", "low", "ground"]
)
def test_one_filament_carries_its_mass_over_the_half_space(
    centre: tuple[float, float, float],
) -> None:
    assert _half_space_integral(centre, 0.2, 0.1) == pytest.approx(0.1, rel=1e-6)


def test_live_filaments_carry_m_each() -> None:
    """The plume's own filaments, integrated one by one: M = Q/n each (Q 2 g/s, n 10 Hz)."""
    plume = _plume(rate_hz=10.0, q=2.0, height=0.3)
    centres, radii = plume.filaments(6.0)
    assert 30 <= centres.shape[0] <= 90  # Poisson: about 60 released in 6 s
    for c, r in zip(centres[:12], radii[:12], strict=True):
        assert _half_space_integral(tuple(c), float(r), 0.2) == pytest.approx(0.2, rel=1e-6)


@pytest.mark.parametrize("step_s", [0.01, 0.05, 0.1])
def test_crosswind_variance_is_2k_age_whatever_the_step(step_s: float) -> None:
    plume = _plume(rate_hz=5000.0, step_s=step_s, max_age_s=4.0)
    k, state = plume.state_at(4.0)
    age = (k - state.birth_step) * step_s
    old = age >= 1.0 - 1e-9
    y = state.positions[old, 1]
    assert y.size >= 10_000
    normalised = y / np.sqrt(2.0 * K * age[old])
    assert float(np.mean(normalised**2)) == pytest.approx(1.0, rel=0.03)
    # downwind the centres move with the wind (u = 1 m/s): x = age exactly, no noise bias
    x = state.positions[old, 0]
    assert float(np.mean(x - age[old])) == pytest.approx(0.0, abs=0.01)


def _analytic(points: np.ndarray, q: float, u: float, h: float) -> np.ndarray:
    x, y, z = points.T
    s2 = R0_2 + (2.0 * K + GAMMA) * x / u
    vertical = np.exp(-((z - h) ** 2) / (2 * s2)) + np.exp(-((z + h) ** 2) / (2 * s2))
    return q / (2 * math.pi * u * s2) * np.exp(-(y**2) / (2 * s2)) * vertical


def test_long_time_average_without_meander_is_the_analytic_plume() -> None:
    """Many light filaments (n 200 Hz, same Q) make the average converge faster; the mean
    does not depend on n."""
    plume = _plume(rate_hz=200.0, q=1.0, height=0.5, max_age_s=10.0)
    points = np.array(
        [[2.0, 0.0, 0.5], [5.0, 0.0, 0.5], [5.0, 0.5, 0.5], [5.0, 0.0, 1.2], [8.0, 0.0, 0.1]]
    )
    times = np.arange(12.0, 162.0, 0.05)
    mean = np.mean([plume.concentration(points, t) for t in times], axis=0)
    assert mean == pytest.approx(_analytic(points, 1.0, 1.0, 0.5), rel=0.10)


def test_large_meander_widens_the_average_and_makes_the_centreline_intermittent() -> None:
    offsets = np.linspace(-15.0, 15.0, 61)
    points = np.column_stack([np.full(61, 20.0), offsets, np.full(61, 2.0)])  # centre: row 30
    times = np.arange(30.0, 270.0, 0.2)

    def average_and_centre(wind: Wind) -> tuple[float, np.ndarray]:
        plume = _plume(rate_hz=20.0, height=2.0, wind=wind, max_age_s=40.0)
        values = np.array([plume.concentration(points, t) for t in times])
        mean = values.mean(axis=0)
        width = math.sqrt(float(np.sum(mean * offsets**2) / np.sum(mean)))
        return width, values[:, 30]

    steady_width, _ = average_and_centre(Wind(speed_m_s=2.0, from_deg=270.0))
    meander = Wind(
        speed_m_s=2.0, from_deg=270.0, model="meander", meander=WindMeander(preset="large")
    )
    wide_width, series = average_and_centre(meander)
    # without meander the crosswind width is s = √(R0² + (2K+γ)x/u) ≈ 0.64 m at 20 m, 2 m/s
    assert steady_width == pytest.approx(math.sqrt(R0_2 + (2 * K + GAMMA) * 20.0 / 2.0), rel=0.25)
    assert wide_width > 2.0 * steady_width
    assert float(np.mean(series > 0.01 * series.mean())) < 0.9


def test_same_seed_same_field_in_any_order_and_after_going_back() -> None:
    points = np.array([[3.0, 0.0, 0.5], [6.0, 0.2, 0.4]])
    times = [1.0, 7.3, 20.0, 55.55]
    one = _plume(rate_hz=50.0)
    forward = [one.concentration(points, t) for t in times]
    again = [one.concentration(points, t) for t in reversed(times)][::-1]  # back in time
    other = _plume(rate_hz=50.0)
    fresh = [other.concentration(points, t) for t in reversed(times)][::-1]
    for a, b, c in zip(forward, again, fresh, strict=True):
        assert a.tobytes() == b.tobytes() == c.tobytes()
    assert _plume(rate_hz=50.0, seed=2).concentration(points, 20.0).tobytes() != (
        forward[2].tobytes()
    )


def test_scenario_sources_superpose_each_with_its_own_stream() -> None:
    scenario = parse_scenario(
        """
[wind]
speed_m_s = 1.0
[plume]
model = "filament"
[[plume.sources]]
release_rate_g_s = 1.0
release_height_m = 1.0
[[plume.sources]]
x_m = 0.0
y_m = 5.0
release_rate_g_s = 2.0
release_height_m = 1.0
[[vehicles]]
id = "a"
"""
    )
    field = field_from_scenario(scenario)
    assert isinstance(field, PlumeField)
    a, b = field.sources
    assert isinstance(a, FilamentPlume) and isinstance(b, FilamentPlume)
    pa, pb = a.filaments(10.0)[0], b.filaments(10.0)[0]
    # different streams: not the same walk shifted by 5 m
    assert not np.allclose(pa[: len(pb), 1] + 5.0, pb[: len(pa), 1])
    points = np.array([[4.0, 0.0, 1.0], [4.0, 5.0, 1.0], [4.0, 2.5, 1.0]])
    total = field.concentration(points, 10.0)
    assert total == pytest.approx(a.concentration(points, 10.0) + b.concentration(points, 10.0))


def _advance_by_masks(
    plume: FilamentPlume, k: int, state: Filaments, rng: np.random.Generator
) -> Filaments:
    """One step written as the model's equations read: every centre moved, the old ones masked
    out, the new ones appended (the reference for the model's own ``advance``)."""
    h = plume.step_s
    p, born = state.positions, state.birth_step
    moved = p + plume.wind.velocity(p, k * h) * h
    noise = plume._noise[np.minimum(k - born, plume._noise.shape[0] - 1)]
    moved += noise * rng.standard_normal(p.shape)
    np.abs(moved[:, 2], out=moved[:, 2])
    alive = (k + 1 - born) <= plume._max_age_steps
    new = int(rng.poisson(plume.params.release_rate_hz * h))
    return Filaments(
        np.concatenate([moved[alive], np.tile(plume.source_m, (new, 1))]),
        np.concatenate([born[alive], np.full(new, k + 1, dtype=np.int64)]),
    )


@pytest.mark.parametrize(
    "wind",
    [
        Wind(speed_m_s=2.0, from_deg=250.0),
        Wind(speed_m_s=1.0, from_deg=270.0, model="meander", meander=WindMeander(preset="large")),
        Wind(speed_m_s=1.0, from_deg=270.0, model="field", meander=WindMeander(preset="large")),
    ],
    ids=["steady", "meander", "field"],
)
def test_advance_is_the_masked_step_bit_for_bit(wind: Wind) -> None:
    # filaments die after 2 s while new ones are born, some steps release none or several
    plume = _plume(rate_hz=30.0, wind=wind, max_age_s=2.0)
    ours, reference = plume.initial_state(), plume.initial_state()
    for k in range(200):
        ours = plume.advance(ours, k, np.random.default_rng(k))
        reference = _advance_by_masks(plume, k, reference, np.random.default_rng(k))
        assert ours.positions.tobytes() == reference.positions.tobytes()
        assert ours.birth_step.tobytes() == reference.birth_step.tobytes()
    assert 30 < len(ours.birth_step) < 90  # ≈ 60 alive: the test saw deaths and births


def test_one_point_is_the_sum_over_the_live_filaments_written_out() -> None:
    """The plume's value at a point (its kernels looked up by age) is Σ M·(2π)^−3/2·R^−3/P₄ ·
    [exp(−d²/2R²) + exp(−d̄²/2R²)] over the live filaments within 4R (d̄: to the ground image),
    summed here one filament at a time; and the per-filament kernel's bits."""
    plume = _plume(rate_hz=20.0, q=2.0, height=1.0, step_s=0.05, max_age_s=6.0)
    p4 = math.erf(2.0 * math.sqrt(2.0)) - 8.0 * math.exp(-8.0) / math.sqrt(2.0 * math.pi)
    checked = 0
    for t in (3.0, 9.0, 9.05, 20.0):  # before and after the first filaments die
        centres, radii = plume.filaments(t)
        masses = np.full(radii.shape[0], plume.mass_g)
        for x, y, z in [(1.0, 0.1, 1.0), (2.5, -0.2, 0.8), (2.0, 0.0, 0.0), (1.5, 0.2, 1.3)]:
            expected = 0.0
            for (cx, cy, cz), r in zip(centres, radii, strict=True):
                for zz in (cz, -cz):
                    d2 = (x - cx) ** 2 + (y - cy) ** 2 + (z - zz) ** 2
                    if d2 < (4.0 * r) ** 2:
                        amplitude = plume.mass_g * (2.0 * math.pi) ** -1.5 / r**3 / p4
                        expected += amplitude * math.exp(-d2 / (2.0 * r * r))
            point = np.array([[x, y, z]])
            value = float(plume.concentration(point, t)[0])
            assert value == pytest.approx(expected, rel=1e-12, abs=1e-300)
            direct = filament_concentration(point, centres, radii, masses)  # kernels per filament
            assert value == float(direct[0])
            checked += value > 0.0
    assert checked >= 6  # not a comparison of zeros: the plume is intermittent at a point
