"""The time-dependent environments of ``plumeswarm bench gsl`` as the bench sees them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.behaviors.detection import PLUME_THRESHOLD_G_M3
from plumeswarm.gsl.episode import (
    FIELD_WARMUP_S,
    START_ALONG_M,
    START_ALTITUDE_M,
    EpisodeSpec,
    _state,
    environment_field,
    episode_behaviors,
    episode_scenario,
)


@pytest.mark.parametrize("along_m", [START_ALONG_M[0], 55.0, START_ALONG_M[1]])
def test_a_vehicle_hovering_on_the_centreline_sees_bursts_and_silences(along_m: float) -> None:
    """``lab_thread``, Farrell's filaments in a steady wind. No meander: filaments (R ≈ 0.1 m
    at 50 m, 0.6 m apart at 6 m/s and 10 Hz) wander about the axis with std √(2K·age) ≈ 0.6 m
    (K = 0.02 m²/s, age ≈ 8 s). A filament's 1 mg/m³ shell is ≈ 0.45 m (from
    M/((2π)^1.5 R³)·e^(−r²/2R²), M = 1 g), so one passes close enough with probability
    ≤ erf(0.45/(0.6·√2))² ≈ 0.3; with about 1.5 filaments within reach along the wind at any
    moment, a sensor hovering on the axis is in the plume well under 60 % of the time (a steady
    plume: 100 %), and in more than 5 % of its samples."""
    spec = EpisodeSpec("casting", "lab_thread", "ideal", 0, 0)
    scenario = episode_scenario(spec)
    field, _ = environment_field(scenario)
    src = scenario.plume.sources[0]
    assert src.release_height_m == START_ALTITUDE_M  # the axis is at the flight altitude
    point = np.array([[src.x_m + along_m, src.y_m, START_ALTITUDE_M]])  # wind toward +x
    times = FIELD_WARMUP_S + np.arange(0.0, 60.0, 0.1)  # the episode's first minute, 10 Hz
    values = np.array([field(point, float(t))[0] for t in times])
    inside = values >= PLUME_THRESHOLD_G_M3
    assert 0.05 < inside.mean() < 0.6, inside.mean()
    # Bursts, not one long dwell: the signal switches on and off many times.
    assert np.count_nonzero(np.diff(inside.astype(int)) == 1) >= 20


def test_the_filament_field_is_the_same_whoever_asks_and_differs_between_runs() -> None:
    point = np.array([[50.0, 0.0, START_ALTITUDE_M]])
    times = FIELD_WARMUP_S + np.arange(0.0, 10.0, 0.1)

    def series(run: int, order: slice) -> dict[float, float]:
        field, _ = environment_field(
            episode_scenario(EpisodeSpec("casting", "meander_low", "ideal", run, 3))
        )
        return {float(t): float(field(point, float(t))[0]) for t in times[order]}

    forward = series(1, slice(None))
    assert forward == series(1, slice(None, None, -1))  # asked backwards: the same values
    assert forward != series(2, slice(None))  # another run, another realisation


@pytest.mark.parametrize(
    "algorithm", ["casting", "surge_cast", "gradient_swarm", "infotaxis", "particle_filter"]
)
def test_behaviours_read_their_anemometer_in_a_meandering_wind(algorithm: str) -> None:
    """Every wind-using behaviour, built as an autopilot builds it, in ``meander_high``: an
    Ornstein–Uhlenbeck meander whose std σv is fitted (Taylor 1921) to 0.8 of class D's σy²
    (McMullen 1975) at 30, 50 and 80 m — ≈ 0.51 m/s, computed here from those formulas. The
    wind a behaviour reads follows the meander (the true wind at its position and time, plus
    0.1 m/s anemometer noise), not the scenario's mean wind of 6 m/s toward +x: its crosswind
    std over 300 s (≈ 20 timescales of 7.4 s: a sampling error of ≈ 16 % of σv) is above
    σv / 2, which the anemometer's noise alone (0.1 m/s) would not reach."""
    spec = EpisodeSpec(algorithm, "meander_high", "ideal", 0, 0)
    scenario = episode_scenario(spec)
    _, wind = environment_field(scenario)
    behavior = episode_behaviors(spec, scenario)[0]
    read, true = [], []
    for k in range(300):
        t = FIELD_WARMUP_S + k
        p = (50.0, 3.0, START_ALTITUDE_M)
        read.append(behavior.read_wind(_state("uav1", k * 20, t, list(p), (0.0, 0.0, 0.0))))  # type: ignore[attr-defined]
        true.append(wind.velocity([p], t)[0][:2])
    error = np.asarray(read) - np.asarray(true)
    assert np.abs(error).max() < 5 * 0.1  # the anemometer's noise only
    assert 0.05 < np.std(error) < 0.15
    sigma_v_m_s = _taylor_meander_std_m_s(share=0.8)
    assert math.isclose(scenario.wind.meander.std_m_s, sigma_v_m_s, rel_tol=0.01)
    assert np.std(np.asarray(read)[:, 1]) > 0.5 * sigma_v_m_s  # the crosswind meander, read


def _taylor_meander_std_m_s(share: float, u_m_s: float = 6.0, z_m: float = 10.0) -> float:
    """σv such that Taylor's σm²(t) = 2σv²T_L[t − T_L(1 − e^(−t/T_L))] fits ``share``·σy² of
    McMullen's class D (σy = exp(4.230 + 0.9222 ln x − 0.0087 ln² x), x in km) at 30, 50,
    80 m, least squares on the relative error; T_L = 0.5 z / (1.3 u*), u* = 0.4 u / ln(z/z0),
    z0 = 0.1 m (Hanna 1982)."""
    ustar = 0.4 * u_m_s / math.log(z_m / 0.1)
    t_l = 0.5 * z_m / (1.3 * ustar)
    ratios = []
    for x_m in (30.0, 50.0, 80.0):
        ln_km = math.log(x_m / 1000.0)
        sigma_y = math.exp(4.230 + 0.9222 * ln_km - 0.0087 * ln_km**2)
        t = x_m / u_m_s
        ratios.append(2.0 * t_l * (t - t_l * (1.0 - math.exp(-t / t_l))) / (share * sigma_y**2))
    return math.sqrt(sum(ratios) / sum(r * r for r in ratios))


def test_an_environment_answers_to_its_listed_name_and_a_near_miss_gets_a_did_you_mean() -> None:
    """``gsl/NAME`` (as ``plumeswarm scenario list`` shows it) is the file ``NAME`` names."""
    import hashlib

    from plumeswarm.gsl.registry import GslError, load_environment
    from swarmbus.scenario import GSL_ENVIRONMENTS_DIR

    data = (GSL_ENVIRONMENTS_DIR / "meander_low.toml").read_bytes()
    listed = load_environment("gsl/meander_low")
    assert listed.name == "meander_low"
    assert listed.sha256 == hashlib.sha256(data).hexdigest()
    with pytest.raises(GslError, match=r"did you mean 'meander_low'\?\); valid: .*puff_meander"):
        load_environment("meandr_low")
