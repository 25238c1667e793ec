"""Cooperative source-term estimation: the members' filters hold the product of the likelihoods
of the windows they have (their own and what the radio brought), computed here from the plume
formula and the zero-inflated likelihood written out again; the correction leaves the
published particle filter's rows unchanged; a swarm of 3 flies an episode."""

from __future__ import annotations

import math

import msgspec
import numpy as np

from agents.behavior import BehaviorContext
from agents.behaviors.coop_ste import CooperativeSTE, Window
from agents.peer_link import PeerLink
from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.plume_formula import gaussian_plume_g_m3
from plumeswarm.gsl.episode import EpisodeSpec, run_episode
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
    """ln Π_k L(window k | particle)^τ: the Gaussian plume (class D, McMullen, 10 m release
    as the scenario's) averaged over each window's points, in the window's wind, under the
    zero-inflated likelihood (p_bg 0.01, p_miss 0.3, scale 0.001 g/m³, σ 1 on ln(c + 1e-4),
    floored at 3σ)."""
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
        total += TEMPERING * log_l
    return total


def normalised(log_w: np.ndarray) -> np.ndarray:
    w = np.exp(log_w - log_w.max())
    return w / w.sum()


def fly_two(scenario: Scenario, seconds: float) -> tuple[list[Member], PeerLink, dict, dict]:
    """Two members 3 m apart across the plume's axis, flying upwind at 2 m/s 40 m downwind of
    the origin, fed readings of a plume that comes and goes (detections in 2 s of every 3),
    their filters on the same particles: the members, the link, what each published and what
    each received."""
    link = PeerLink(scenario)
    members = []
    for i, vid in enumerate(("uav1", "uav2")):
        rng = np.random.Generator(np.random.PCG64(7))  # the same prior draws
        members.append(Member(BehaviorContext(vid, i, scenario, 0.05, rng, link.mailboxes[vid])))
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
    a, b = (m.filter for m in members)
    assert a is not None and b is not None
    np.testing.assert_array_equal(a.particles, b.particles)  # never resampled
    np.testing.assert_allclose(a.weights, b.weights, rtol=1e-9, atol=1e-300)
    expected = normalised(expected_log_weights(a.particles, windows))
    np.testing.assert_allclose(a.weights, expected, rtol=1e-6, atol=1e-12)
    assert a.weights.max() > 10.0 / len(a.weights)  # the readings did move the weights
    for w in windows:
        assert len(msgspec.msgpack.encode(w)) <= IDEAL.radio.max_message_bytes


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
