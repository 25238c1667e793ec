"""The scenario's one wind (plume_atmosphere.wind): steady equivalence, the meander SDE, the grid
wind."""

from __future__ import annotations

import math
from typing import Literal

import numpy as np
import pytest

from plume_atmosphere.wind import ColouredNoise, SteadyWind, wind_model
from swarmbus.scenario import Wind, WindField, WindMeander, parse_scenario

VEHICLE = '[[vehicles]]\nid = "a"\n'


def test_steady_is_the_mean_wind_everywhere_and_always() -> None:
    wind = wind_model(Wind(speed_m_s=6.0, from_deg=270.0), seed=1)
    assert isinstance(wind, SteadyWind)
    values = wind.velocity([[0.0, 0.0, 0.0], [50.0, -3.0, 10.0]], 123.4)
    assert values == pytest.approx(np.array([[6.0, 0.0, 0.0]] * 2), abs=1e-12)
    # from the north (0°) blows toward −y
    south = wind_model(Wind(speed_m_s=2.0, from_deg=0.0), seed=1).velocity([[0, 0, 0]], 0.0)
    assert south[0] == pytest.approx([0.0, -2.0, 0.0], abs=1e-12)


def test_scenario_wind_defaults_to_steady_and_presets_resolve() -> None:
    s = parse_scenario(VEHICLE)
    assert s.wind.model == "steady"
    s = parse_scenario('[wind]\nmodel = "meander"\n[wind.meander]\npreset = "large"\n' + VEHICLE)
    m = s.wind.meander.resolved()
    assert (m.gain, m.damping, m.bandwidth_rad_s) == (20.0, 0.1, 0.2)


@pytest.mark.parametrize(("preset", "expected_std"), [("small", 0.47), ("large", 1.41)])
@pytest.mark.parametrize("step_s", [0.01, 0.05, 0.1])
def test_meander_stationary_std_is_independent_of_step(
    preset: Literal["small", "large"], expected_std: float, step_s: float
) -> None:
    """Farrell's presets: G √(0.01 s) √(ω/4ζ) = 0.474 (small), 1.414 m/s (large), by hand."""
    copies = 2000
    noise = ColouredNoise(WindMeander(preset=preset, step_s=step_s), copies, seed=7, stream=0)
    # Well past the process's decay time 1/(ζω) (14 s small, 50 s large): an integrator whose
    # variance drifted with the step would show it here.
    sample = noise.at(100.0)
    assert sample.std() == pytest.approx(expected_std, rel=0.05)
    assert abs(sample.mean()) < 4 * expected_std / math.sqrt(copies)


def test_meander_time_series_has_the_damped_oscillator_spectrum_peak() -> None:
    """The autocorrelation of the small preset first crosses zero near a quarter period
    π/(2ω_d), ω_d = ω√(1−ζ²) (a lightly damped oscillator), by hand ≈ 2.22 s."""
    noise = ColouredNoise(WindMeander(preset="small", step_s=0.05), 200, seed=3, stream=0)
    x = np.stack([noise.values(k) for k in range(0, 4000)])  # 200 s
    x = x - x.mean(axis=0)
    lags = np.arange(0, 80)
    acf = np.array([np.mean(x[: len(x) - lag] * x[lag:]) for lag in lags])
    first_negative = int(np.argmax(acf < 0)) * 0.05
    omega_d = 0.71 * math.sqrt(1 - 0.071**2)
    assert first_negative == pytest.approx(math.pi / (2 * omega_d), abs=0.15)


def test_meander_is_deterministic_whatever_the_query_order() -> None:
    config = Wind(model="meander", meander=WindMeander(preset="large"))
    times = [0.0, 0.37, 12.5, 99.99, 250.0]
    forward = wind_model(config, seed=11)
    backward = wind_model(config, seed=11)
    a = [forward.velocity([[1.0, 2.0, 3.0]], t) for t in times]
    b = [backward.velocity([[1.0, 2.0, 3.0]], t) for t in reversed(times)][::-1]
    for x, y in zip(a, b, strict=True):
        assert x.tobytes() == y.tobytes()
    other = wind_model(config, seed=12).velocity([[1.0, 2.0, 3.0]], 12.5)
    assert other.tobytes() != a[2].tobytes()
    # the meander rides on the mean wind: its long-run mean is the mean wind
    series = np.array([forward.velocity([[0, 0, 0]], t)[0] for t in np.arange(0, 3000, 1.0)])
    assert series[:, 0].mean() == pytest.approx(6.0, abs=0.3)
    assert series[:, 2].tolist() == [0.0] * len(series)


def test_grid_wind_is_deterministic_after_going_back_in_time() -> None:
    config = Wind(
        model="field",
        meander=WindMeander(preset="small"),
        field=WindField(spacing_m=20.0, extent_m=100.0, diffusivity_m2_s=1.0),
    )
    points = [[0.0, 0.0, 5.0], [-90.0, 40.0, 5.0], [500.0, 0.0, 0.0]]
    one = wind_model(config, seed=5)
    late = one.velocity(points, 30.0)
    early = one.velocity(points, 4.0)  # going back: restored from a checkpoint
    fresh = wind_model(config, seed=5)
    assert fresh.velocity(points, 4.0).tobytes() == early.tobytes()
    assert fresh.velocity(points, 30.0).tobytes() == late.tobytes()
    # outside the grid the edge value holds; the field varies in space
    assert not np.allclose(late[0], late[1])
    assert np.all(np.abs(late[:, :2] - [6.0, 0.0]) < 5.0)


def test_grid_wind_goes_back_past_thinned_checkpoints() -> None:
    """Old checkpoints are thinned (newest 32 blocks kept, then every 16th block): going back
    to before a dropped checkpoint restarts from an older one and gives the same bits."""
    config = Wind(
        model="field",
        meander=WindMeander(preset="small", step_s=0.5),
        field=WindField(spacing_m=50.0, extent_m=100.0),
    )
    one = wind_model(config, seed=5)
    point = [[10.0, -20.0, 3.0]]
    late = one.velocity(point, 0.5 * 64 * 40)  # 40 blocks: blocks 1–7 thinned away
    early = one.velocity(point, 0.5 * 64 * 5 + 3.0)
    fresh = wind_model(config, seed=5)
    assert fresh.velocity(point, 0.5 * 64 * 5 + 3.0).tobytes() == early.tobytes()
    assert one.velocity(point, 0.5 * 64 * 40).tobytes() == late.tobytes()
