"""The wind's local turbulence (``[wind.turbulence]``): a seeded, spatially correlated field
frozen in the frame of the mean wind. Its statistics against the closed form of the field
(variance σ², correlation exp(−r/L)·exp(−τ/T)), and one field for the plume and the
anemometers. Its derivation from the stability class and the calibrated plume's time average
with it on: test_plume_calibration.py."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from agents.anemometer import Anemometer
from plume_atmosphere.wind import TurbulenceField, wind_from_scenario
from plume_service.filament import FilamentPlume
from plume_service.from_scenario import field_from_scenario
from swarmbus.scenario import (
    AnemometerSpec,
    ScenarioError,
    WindTurbulence,
    parse_scenario,
)

STD = (0.8, 0.5, 0.3)
LENGTH_M, TIMESCALE_S = 10.0, 5.0
MEAN = (6.0, 0.0, 0.0)  # toward +x: along = east, across = north


def _config(modes: int = 64) -> WindTurbulence:
    return WindTurbulence(
        std_m_s=STD, length_scale_m=LENGTH_M, timescale_s=TIMESCALE_S, modes=modes
    )


_TOML = """
[world]
seed = 7
[wind]
speed_m_s = 6.0
model = "{model}"
[wind.turbulence]
share = {share}
[plume]
model = "filament"
[plume.filament]
centerline_diffusivity_m2_s = 0.0
max_age_s = 20.0
[[vehicles]]
id = "a"
"""


def test_the_field_is_a_deterministic_function_of_the_seed_position_and_time() -> None:
    scenario = parse_scenario(_TOML.format(model="meander", share=0.3))
    first, second = wind_from_scenario(scenario), wind_from_scenario(scenario)
    points = np.random.default_rng(1).uniform(-100.0, 100.0, (50, 3))
    times = [0.0, 12.3, 4.05, 300.0]
    forward = [first.velocity(points, t) for t in times]
    backward = [second.velocity(points, t) for t in reversed(times)][::-1]
    for a, b in zip(forward, backward, strict=True):
        assert np.array_equal(a, b)
    one_by_one = np.array([second.velocity(points[i : i + 1], 12.3)[0] for i in range(50)])
    assert np.array_equal(one_by_one, forward[1])
    other = msgspec.structs.replace(scenario.world, seed=8)
    moved = wind_from_scenario(msgspec.structs.replace(scenario, world=other))
    assert not np.allclose(moved.velocity(points, 12.3), forward[1])
    # it varies in space: the wind is not the same at two points 30 m apart
    pair = first.velocity([(0.0, 0.0, 10.0), (0.0, 30.0, 10.0)], 5.0)
    assert not np.allclose(pair[0], pair[1], atol=1e-3)


def test_its_variance_over_space_is_the_configured_intensity() -> None:
    # σ²·(2/M)·Σ cos²: its mean over a domain much larger than L is σ² in every realisation
    field = TurbulenceField(_config(), MEAN, seed=3)
    points = np.random.default_rng(4).uniform(-1000.0, 1000.0, (20_000, 3))
    values = field.at(points, 17.0)
    measured = np.sqrt((values**2).mean(axis=0))
    assert measured == pytest.approx(STD, rel=0.05)


def _correlation(lags: list[tuple[float, float, float]], dt: float, seeds: int = 16) -> np.ndarray:
    """(lags, 3): E[u(x, t)·u(x + lag, t + dt)] / σ² per component, over points and
    realisations."""
    rng = np.random.default_rng(5)
    out = np.zeros((len(lags), 3))
    for seed in range(seeds):
        field = TurbulenceField(_config(), MEAN, seed=seed)
        p = rng.uniform(-500.0, 500.0, (2000, 3))
        a = field.at(p, 10.0)
        for i, lag in enumerate(lags):
            b = field.at(p + np.asarray(lag), 10.0 + dt)
            out[i] += (a * b).mean(axis=0) / np.asarray(STD) ** 2
    return out / seeds


def test_its_spatial_correlation_is_exponential_in_the_length_scale() -> None:
    ratios = (0.5, 1.0, 2.0)
    across = _correlation([(0.0, r * LENGTH_M, 0.0) for r in ratios], 0.0)
    for r, rho in zip(ratios, across, strict=True):
        assert rho == pytest.approx(np.full(3, math.exp(-r)), abs=0.07), r


def test_its_correlation_length_is_the_configured_one() -> None:
    # the e-folding length of the correlation, a least-squares fit of ln ρ = −r/L over
    # 0.25–1 L along each axis (farther, ρ's sampling error dominates its logarithm): exp(−r/L)
    # has integral length scale L
    r = np.array([0.25, 0.5, 0.75, 1.0]) * LENGTH_M
    for axis in range(3):
        lags = [tuple(float(ri) if a == axis else 0.0 for a in range(3)) for ri in r]
        rho = _correlation(lags, 0.0)  # type: ignore[arg-type]
        fitted = -float((r * r).sum()) / (r[:, None] * np.log(rho)).sum(axis=0)
        assert fitted == pytest.approx(np.full(3, LENGTH_M), rel=0.1), axis


def test_it_is_frozen_in_the_mean_wind_and_decorrelates_over_its_timescale() -> None:
    # moved with the mean wind for τ = T the correlation is exp(−1); at rest, the eddies go by
    tau = TIMESCALE_S
    carried, at_rest = _correlation([(MEAN[0] * tau, 0.0, 0.0), (0.0, 0.0, 0.0)], tau)
    assert carried == pytest.approx(np.full(3, math.exp(-1.0)), abs=0.07)
    expected = math.exp(-MEAN[0] * tau / LENGTH_M) * math.exp(-1.0)
    assert at_rest == pytest.approx(np.full(3, expected), abs=0.05)


def test_without_the_section_the_wind_is_as_before() -> None:
    s = parse_scenario('[wind]\nmodel = "meander"\n[[vehicles]]\nid = "a"\n')
    assert s.wind.turbulence is None
    wind = wind_from_scenario(s)
    assert wind.uniform_at(3.0) is not None and "turbulence" not in wind.info()


@pytest.mark.parametrize(
    ("text", "field"),
    [
        (_TOML.format(model="steady", share=0.9), "wind.turbulence.share"),
        (
            _TOML.format(model="meander", share=0.5) + "[plume.calibration]\nmeander_share = 0.6\n",
            "wind.turbulence.share",
        ),
    ],
)
def test_a_bad_share_is_one_line(text: str, field: str) -> None:
    # the second: meander 0.6 + turbulence 0.5 leave no variance for the filaments
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text, "x.toml")
    assert err.value.field == field and "\n" not in str(err.value)


def test_an_anemometer_reads_the_wind_that_carries_the_filaments_there() -> None:
    # no relative diffusion: a filament's step is exactly the wind at its place and time
    scenario = parse_scenario(_TOML.format(model="meander", share=0.3))
    plume = field_from_scenario(scenario)
    assert isinstance(plume, FilamentPlume)
    anemometer = Anemometer(
        AnemometerSpec(period_ticks=1, noise_std_m_s=0.0), wind_from_scenario(scenario), 7, 0
    )
    h = plume.step_s
    k, state = plume.state_at(10.0)
    before = {int(b): p.copy() for b, p in zip(state.birth_step, state.positions, strict=True)}
    _, after = plume.state_at(10.0 + h)
    checked = 0
    for b, p in zip(after.birth_step, after.positions, strict=True):
        start = before.get(int(b))
        if start is None or start[2] < 1.0:  # newborn, or near the ground's reflection
            continue
        reading = anemometer.read("a", k, k * h, (start[0], start[1], start[2]))
        expected = start + np.asarray(reading.true_wind_enu_m_s) * h
        assert np.array_equal(p, expected)
        checked += 1
    assert checked > 50
    # and the readings differ from place to place: not the one uniform wind
    spread = np.array(
        [
            anemometer.read("a", k, k * h, (x, 0.0, 10.0)).true_wind_enu_m_s
            for x in (10.0, 40.0, 70.0)
        ]
    )
    assert spread[:, 1].std() > 0.01
