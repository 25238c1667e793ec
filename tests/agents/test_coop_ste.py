"""Cooperative source-term estimation: the members' filters hold the product of the likelihoods
of the windows they have (their own and what the radio brought), computed here from the plume
formula and the zero-inflated likelihood written out again; each window's weight comes from
its member's own anemometer (never from the scenario's meander), near the closed form of an
Ornstein–Uhlenbeck wind; the correction leaves the published particle filter's rows
unchanged; a swarm of 3 flies an episode."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest

from agents.behavior import BehaviorContext
from agents.behaviors.coop_ste import CooperativeSTE, Window
from agents.behaviors.particle_filter import effective_fraction
from agents.behaviors.wind import WindReader
from agents.peer_link import PeerLink
from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.plume_formula import gaussian_plume_g_m3
from plumeswarm.gsl.episode import EpisodeSpec, run_episode
from swarmbus.messages import VehicleState
from swarmbus.radio import RadioSpec
from swarmbus.scenario import Scenario, Sensor, VehicleSpec, load_scenario
from tests.support.messages_samples import reading, vehicle_state
from tests.support.published import published_and_reflown

SCENARIO = load_scenario()  # wind 6 m/s toward +x, class D
IDEAL = msgspec.structs.replace(
    SCENARIO,
    sensor=Sensor(preset="ideal"),
    anemometer=msgspec.structs.replace(SCENARIO.anemometer, noise_std_m_s=0.0),
    vehicles=[VehicleSpec(id=v) for v in ("uav1", "uav2")],
)
TEMPERING = 0.1  # correlation time 5 s, 1 s windows: 1 / (2 × 5)


class Member(CooperativeSTE):
    correlation_time_s = 5.0


def expected_log_weights(particles: np.ndarray, windows: list[Window]) -> np.ndarray:
    """ln Π_k L(window k | particle)^τₖ, τₖ the window's weight: the Gaussian plume (class D,
    McMullen, 10 m release as the scenario's) averaged over each window's points, in the
    window's wind, under the zero-inflated likelihood (p_bg 0.01, p_miss 0.3, scale
    0.001 g/m³, σ 1 on ln(c + 1e-4), floored at 3σ)."""
    plume = SCENARIO.plume
    curves = dispersion_curves(plume.coefficients, plume.stability)
    total = np.zeros(len(particles))
    for w in windows:
        speed = math.hypot(w.wind_e_m_s, w.wind_n_m_s)
        de, dn = w.wind_e_m_s / speed, w.wind_n_m_s / speed
        c = np.zeros(len(particles))
        for x_cm, y_cm in zip(w.x_cm, w.y_cm, strict=True):
            dx, dy = x_cm / 100.0 - particles[:, 0], y_cm / 100.0 - particles[:, 1]
            along, across = dx * de + dy * dn, -dx * dn + dy * de
            c += gaussian_plume_g_m3(
                along, across, w.z_m, particles[:, 2], speed, plume.sources[0].release_height_m,
                curves,
            )  # fmt: skip
        c /= len(w.x_cm)
        p = np.minimum(0.01 + 0.99 * (1.0 - np.exp(-c / 0.001)), 0.7)
        if w.detected:
            r = np.log(w.mean_g_m3 + 1e-4) - np.log(c + 1e-4)
            log_l = np.log(p) - 0.5 * np.minimum(r**2, 9.0)
        else:
            log_l = np.log(1.0 - p)
        total += w.tempering * log_l
    return total


def normalised(log_w: np.ndarray) -> np.ndarray:
    w = np.exp(log_w - log_w.max())
    return w / w.sum()


def fly_two(
    scenario: Scenario, seconds: float, member: type[CooperativeSTE] = Member, ou_s: float = 0.0
) -> tuple[list[CooperativeSTE], PeerLink, dict, dict]:
    """Two members 3 m apart across the plume's axis, flying upwind at 2 m/s 40 m downwind of
    the origin, fed readings of a plume that comes and goes (detections in 2 s of every 3),
    their filters on the same particles: the members, the link, what each published and what
    each received. ``ou_s`` > 0: each member's anemometer reads its own OU wind of that
    timescale (:func:`ou_winds`)."""
    link = PeerLink(scenario)
    members = []
    for i, vid in enumerate(("uav1", "uav2")):
        rng = np.random.Generator(np.random.PCG64(7))  # the same prior draws
        beh = member(BehaviorContext(vid, i, scenario, 0.05, rng, link.mailboxes[vid]))
        if ou_s > 0.0:
            beh.read_wind = wind_reader(ou_winds(ou_s, seconds + 3.0, seed=20 + i))
        members.append(beh)
    published: dict[str, list[Window]] = {"uav1": [], "uav2": []}
    received: dict[str, list[Window]] = {"uav1": [], "uav2": []}
    ticks = int(seconds * 20)
    for tick in range(ticks + 40):  # 2 s more: every late message has arrived
        t = tick * 0.05
        link.before_step(tick)
        states = []
        for i, beh in enumerate(members):
            vid = f"uav{i + 1}"
            received[vid] += [r.message for r in link.mailboxes[vid].inbox]  # type: ignore[misc]
            pos = (40.0 - 2.0 * t, -1.5 + 3.0 * i, 10.0)
            states.append(vehicle_state(vid, tick, pos, sim_time_s=t, lat_deg=0.0, lon_deg=0.0))
            value = (0.004 + 0.002 * i) if int(t) % 3 else 0.0
            readings = [reading(vid, t, pos, value)] if tick % 2 == 0 and tick < ticks else []
            beh.step(states[-1], [], readings)
            if tick == 0:  # the filter is made: no resampling, no redraw (the product alone)
                assert beh.filter is not None and members[0].filter is not None
                beh.filter.resample_below, beh.filter.prior = 0.0, None
                beh.filter.particles = members[0].filter.particles.copy()  # the same particles
            published[vid] += list(link.mailboxes[vid].outbox)  # type: ignore[arg-type]
        link.after_step(tick, states)
    return members, link, published, received


def test_under_a_perfect_radio_two_members_hold_the_same_weights() -> None:
    members, _, published, received = fly_two(IDEAL, 10.0)
    assert received["uav1"] == published["uav2"] and received["uav2"] == published["uav1"]
    windows = published["uav1"] + published["uav2"]
    assert len(windows) >= 18 and any(w.detected for w in windows)
    assert all(w.tempering == TEMPERING for w in windows)
    a, b = (m.filter for m in members)
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.particles, b.particles)  # never resampled
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-9, atol=1e-300)
    expected = normalised(expected_log_weights(a.particles, windows))
    np.testing.assert_allclose(a.weights, expected, rtol=1e-6, atol=1e-12)
    assert a.weights.max() > 10.0 / len(a.weights)  # the readings did move the weights
    for w in windows:
        assert len(msgspec.msgpack.encode(w)) <= IDEAL.radio.max_message_bytes


def test_members_apply_each_window_with_the_weight_its_sender_measured() -> None:
    """Each member weighs its windows by its own winds (two different OU winds of timescale
    3 s): the windows carry different weights, and both filters still hold the same product."""
    members, _, published, received = fly_two(IDEAL, 20.0, CooperativeSTE, ou_s=3.0)
    assert received["uav1"] == published["uav2"] and received["uav2"] == published["uav1"]
    for own in published.values():
        winds = [(w.wind_e_m_s, w.wind_n_m_s) for w in own]
        assert [w.tempering for w in own] == [
            effective_fraction(winds[: k + 1]) for k in range(len(own))
        ]
    first, second = ([w.tempering for w in published[v]] for v in ("uav1", "uav2"))
    assert first != second and min(first + second) < 0.5
    windows = published["uav1"] + published["uav2"]
    a, b = (m.filter for m in members)
    assert a is not None and b is not None
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-9, atol=1e-300)
    expected = normalised(expected_log_weights(a.particles, windows))
    np.testing.assert_allclose(a.weights, expected, rtol=1e-6, atol=1e-12)


def test_a_window_the_radio_loses_is_not_in_the_receivers_filter_and_late_ones_are() -> None:
    lossy = msgspec.structs.replace(IDEAL, radio=RadioSpec(loss=0.5, latency_ticks=30))
    members, link, published, received = fly_two(lossy, 10.0)
    lost = [w for w in published["uav1"] if w not in received["uav2"]]
    assert lost and len(received["uav2"]) > 0 and link.counts[("uav1", "uav2")].dropped > 0
    b = members[1].filter
    assert b is not None
    own_and_arrived = published["uav2"] + received["uav2"]  # 1.5 s late, applied on arrival
    np.testing.assert_allclose(
        b.weights, normalised(expected_log_weights(b.particles, own_and_arrived)), rtol=1e-6,
        atol=1e-12,
    )  # fmt: skip
    with_lost = normalised(expected_log_weights(b.particles, own_and_arrived + lost))
    assert np.abs(b.weights - with_lost).max() > 1e-3 * b.weights.max()


def test_without_a_mailbox_a_member_flies_alone_on_its_own_windows() -> None:
    rng = np.random.Generator(np.random.PCG64(7))
    beh = Member(BehaviorContext("uav1", 0, IDEAL, 0.05, rng))
    for tick in range(30):
        t = tick * 0.05
        state = vehicle_state("uav1", tick, (40.0, 0.0, 10.0), sim_time_s=t, lat_deg=0.0,
                              lon_deg=0.0)  # fmt: skip
        beh.step(state, [], [reading("uav1", t, (40.0, 0.0, 10.0), 0.003)])
    assert beh.filter is not None and len(beh.window_points) == 1


def test_the_correction_leaves_the_published_particle_filter_rows_unchanged() -> None:
    """Runs 0–1 of particle_filter in meander_high (seed 0, ideal sensor) as the published
    results/gsl-ideal/runs.csv has them, byte for byte."""
    published, new = published_and_reflown("gsl-ideal", "particle_filter", "meander_high", 2)
    assert len(published) == 2
    assert new == published


def test_a_swarm_of_three_flies_an_episode_end_to_end() -> None:
    spec = EpisodeSpec("coop_ste", "meander_low", "ideal", 0, 1000, 30.0)
    outcome = run_episode(spec)
    assert outcome.spec.vehicles == 0 and outcome.closest_approach_m is not None  # a swarm
    assert outcome.total_path_m > 3 * 30.0  # each of the three flew most of the 30 s at 2 m/s


def ou_winds(timescale_s: float, seconds: float, seed: int) -> np.ndarray:
    """An (east, north) wind at 20 Hz: 6 m/s toward +x plus an Ornstein–Uhlenbeck fluctuation
    of timescale ``timescale_s`` and std 0.5 m/s on each axis (exact discretisation)."""
    rng = np.random.default_rng(seed)
    a = math.exp(-0.05 / timescale_s)
    n = int(seconds * 20) + 1
    noise = rng.normal(0.0, 0.5 * math.sqrt(1.0 - a * a), size=(n, 2))
    x = np.empty((n, 2))
    x[0] = rng.normal(0.0, 0.5, size=2)
    for i in range(1, n):
        x[i] = a * x[i - 1] + noise[i]
    return x + np.array([6.0, 0.0])


def wind_reader(winds: np.ndarray) -> WindReader:
    """An anemometer that reads ``winds[tick]``."""

    def read(own: VehicleState) -> tuple[float, float]:
        return float(winds[own.tick, 0]), float(winds[own.tick, 1])

    return read


def ou_window_fraction(timescale_s: float, window_s: float) -> float:
    """n_eff / n of the window means of an OU process of timescale T over windows of D: the
    variance of a window's mean, 2σ²(T/D)²(D/T − 1 + e^(−D/T)), over the long-run variance per
    window, 2σ²T/D: 1 − (T/D)(1 − e^(−D/T)) (≈ D / 2T for T ≫ D)."""
    ratio = timescale_s / window_s
    return 1.0 - ratio * (1.0 - math.exp(-1.0 / ratio))


def fly_alone(
    member: type[CooperativeSTE], scenario: Scenario, winds: np.ndarray
) -> tuple[CooperativeSTE, list[Window]]:
    """One member flying upwind at 2 m/s from 40 m downwind of the origin, its anemometer
    reading ``winds`` (one a tick), fed the coming-and-going readings of :func:`fly_two`:
    the member and the windows it published."""
    link = PeerLink(scenario)
    rng = np.random.Generator(np.random.PCG64(7))
    beh = member(BehaviorContext("uav1", 0, scenario, 0.05, rng, link.mailboxes["uav1"]))
    beh.read_wind = wind_reader(winds)
    published: list[Window] = []
    for tick in range(len(winds)):
        t = tick * 0.05
        link.before_step(tick)
        pos = (40.0 - 2.0 * t, 0.0, 10.0)
        state = vehicle_state("uav1", tick, pos, sim_time_s=t, lat_deg=0.0, lon_deg=0.0)
        value = 0.004 if int(t) % 3 else 0.0
        beh.step(state, [], [reading("uav1", t, pos, value)] if tick % 2 == 0 else [])
        published += list(link.mailboxes["uav1"].outbox)  # type: ignore[arg-type]
        link.after_step(tick, [state])
    return beh, published


def test_a_members_weights_do_not_depend_on_the_scenarios_meander_timescale() -> None:
    """Two meandering scenarios that differ only in ``[wind.meander] timescale_s`` (7.38 s and
    100 s), the same anemometer winds and readings: the same windows, the same weights."""
    base = load_scenario("swarmbus/scenarios/gsl/meander_low.toml")
    assert base.wind.model == "meander" and base.wind.meander.process == "ou"
    winds = ou_winds(5.0, 20.0, seed=11)
    flown = []
    for timescale_s in (base.wind.meander.timescale_s, 100.0):
        meander = msgspec.structs.replace(base.wind.meander, timescale_s=timescale_s)
        wind = msgspec.structs.replace(base.wind, meander=meander)
        scenario = msgspec.structs.replace(IDEAL, wind=wind)
        flown.append(fly_alone(CooperativeSTE, scenario, winds))
    (a, windows_a), (b, windows_b) = flown
    assert len(windows_a) >= 18 and windows_a == windows_b
    assert a.filter is not None and b.filter is not None
    np.testing.assert_array_equal(a.filter.weights, b.filter.weights)


def test_the_online_weight_of_an_ou_wind_is_its_closed_form() -> None:
    """The estimator the members use, on the 1 s means of a 20 Hz OU wind of timescale 5 s
    (4000 windows): n_eff / n within 20 % of the closed form, 0.094."""
    winds = ou_winds(5.0, 4000.0, seed=5)[:-1].reshape(4000, 20, 2).mean(axis=1)
    expected = ou_window_fraction(5.0, 1.0)
    assert expected == pytest.approx(0.0937, abs=1e-4)
    assert effective_fraction(winds) == pytest.approx(expected, rel=0.2)


def test_each_window_carries_the_weight_of_its_members_own_winds() -> None:
    """A member alone for 300 s in an OU wind of timescale 5 s: each window's weight is n_eff
    / n of the mean winds of its windows so far (as the window reports them), 1 for the first
    three, and at the end within a factor of 2 of the closed form (300 windows)."""
    _, windows = fly_alone(CooperativeSTE, IDEAL, ou_winds(5.0, 300.0, seed=3))
    assert len(windows) >= 280  # a window closes on the first tick 1 s after its start
    winds = [(w.wind_e_m_s, w.wind_n_m_s) for w in windows]
    for k, w in enumerate(windows):
        assert w.tempering == effective_fraction(winds[: k + 1])
    assert [w.tempering for w in windows[:3]] == [1.0, 1.0, 1.0]
    expected = ou_window_fraction(5.0, 1.0)
    assert expected / 2.0 < windows[-1].tempering < 2.0 * expected
