"""Cooperative infotaxis: alone it is infotaxis; in a swarm each member's posterior is the
product of the likelihoods of the observations it holds, whatever the radio lost or delayed."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import msgspec
import numpy as np
import pytest

from agents.behavior import BehaviorContext
from agents.behaviors.coop_infotaxis import CooperativeInfotaxis, Observation
from agents.behaviors.infotaxis import Infotaxis
from agents.behaviors.infotaxis_core import FloatArray
from agents.behaviors.wind import WindFrame
from agents.peer_link import PeerLink
from plumeswarm.gsl.bench import make_options, rows_of, run_all
from plumeswarm.gsl.episode import EpisodeSpec, run_episode
from plumeswarm.gsl.registry import BUILTIN_ALGORITHMS
from swarmbus.radio import RadioSpec
from swarmbus.scenario import Scenario, Sensor, VehicleSpec, load_scenario
from tests.support.messages_samples import reading, vehicle_state

BEHAVIOR = BUILTIN_ALGORITHMS["coop_infotaxis"].behavior
DT = 0.05
BASE = load_scenario()  # wind 6 m/s toward +x, source at the origin
IDEAL = msgspec.structs.replace(
    BASE,
    sensor=Sensor(preset="ideal"),
    anemometer=msgspec.structs.replace(BASE.anemometer, noise_std_m_s=0.0),
)


def pair(radio: RadioSpec) -> Scenario:
    """Two members 4 m apart across the wind, 40 m downwind of the source."""
    vehicles = [
        VehicleSpec(id=f"uav{i + 1}", behavior=BEHAVIOR, spawn_enu_m=(40.0, y, 0.0))
        for i, y in enumerate((-2.0, 2.0))
    ]
    return msgspec.structs.replace(IDEAL, vehicles=vehicles, radio=radio)


def gas(x: float, y: float, tick: int) -> float:
    """A plume along +x from the origin, 0.15·x wide either side, present 3 ticks in 9."""
    return 0.01 if x > 0.0 and abs(y) < 0.15 * x and tick % 9 < 3 else 0.0


@dataclass
class Flight:
    members: dict[str, CooperativeInfotaxis]
    #: (tick, message) each member published, and each received (arrival tick)
    published: dict[str, list[tuple[int, Observation]]] = field(default_factory=dict)
    received: dict[str, list[tuple[int, Observation]]] = field(default_factory=dict)


class ConcentrationMember(CooperativeInfotaxis):
    likelihood = "concentration"


def fly(
    scenario: Scenario, seconds: float, member: type[CooperativeInfotaxis] = CooperativeInfotaxis
) -> Flight:
    """The members flown as point masses through the scenario's radio, each reading
    :func:`gas` every tick."""
    link = PeerLink(scenario)
    ids = [v.id for v in scenario.vehicles]
    members = {
        vid: member(
            BehaviorContext(vid, i, scenario, DT, np.random.default_rng(i), link.mailboxes[vid])
        )
        for i, vid in enumerate(ids)
    }
    flight = Flight(members, {vid: [] for vid in ids}, {vid: [] for vid in ids})
    at = {v.id: [v.spawn_enu_m[0], v.spawn_enu_m[1], 10.0] for v in scenario.vehicles}
    for tick in range(round(seconds / DT)):
        t = tick * DT
        link.before_step(tick)
        states = [vehicle_state(vid, tick, (at[vid][0], at[vid][1], 10.0), sim_time_s=t)
                  for vid in ids]  # fmt: skip
        velocity = {}
        for vid, state in zip(ids, states, strict=True):
            box = link.mailboxes[vid]
            for r in box.inbox:
                assert isinstance(r.message, Observation)
                flight.received[vid].append((tick, r.message))
            p = at[vid]
            sp = members[vid].step(
                state, [], [reading(vid, t, (p[0], p[1], 10.0), gas(p[0], p[1], tick))]
            )
            flight.published[vid] += [(tick, m) for m in box.outbox if isinstance(m, Observation)]
            v = sp.velocity_enu_m_s if sp is not None else None
            velocity[vid] = v[:2] if v is not None else (0.0, 0.0)
        link.after_step(tick, states)
        for vid in ids:
            at[vid][0] += velocity[vid][0] * DT
            at[vid][1] += velocity[vid][1] * DT
    return flight


def held(flight: Flight, vid: str) -> list[Observation]:
    """What ``vid``'s posterior holds: its own observations (each applied at the step it is
    published) and every peer's that arrived by its last step."""
    own = flight.published[vid]
    last = own[-1][0]
    return [m for _, m in own] + [m for tick, m in flight.received[vid] if tick <= last]


def product_posterior(member: CooperativeInfotaxis, observations: list[Observation],
                      start: FloatArray | None = None) -> FloatArray:  # fmt: skip
    """``start`` (the uniform prior) times each observation's likelihood of its hits (the
    encounter model's table at the observation's place, duration and wind), to the power
    of the evidence weight, normalised: Bayes' rule for independent observations."""
    assert member.belief is not None
    post = np.ones_like(member.belief) if start is None else start.copy()
    for o in observations:
        frame = WindFrame.of((o.wind_east_m_s, o.wind_north_m_s))
        table = member.likelihoods(frame, o.x_m, o.y_m, o.dt_s)
        post = post * table[min(o.hits, member.n_classes - 1)] ** member.evidence_weight
    return post / post.sum()


def test_with_one_vehicle_it_flies_infotaxis_bit_for_bit() -> None:
    outcomes = [
        run_episode(EpisodeSpec(name, "meander_low", "ideal", 8, 1000, 40.0, keep_trajectory=True,
                                behavior=BUILTIN_ALGORITHMS[name].behavior, vehicles=1))
        for name in ("infotaxis", "coop_infotaxis")
    ]  # fmt: skip
    plain, coop = (
        dataclasses.asdict(dataclasses.replace(o, spec=outcomes[0].spec)) for o in outcomes
    )
    assert plain["detections_per_min"] > 0.0  # it met gas: hits went into its belief
    assert coop == plain


def test_under_a_perfect_radio_the_members_hold_the_product_of_the_same_likelihoods() -> None:
    flight = fly(pair(RadioSpec()), 8.0)
    a, b = flight.members["uav1"], flight.members["uav2"]
    assert a.grid_origin == b.grid_origin  # one grid for the swarm
    # two members: every observation counts as 1/√2 of a lone searcher's
    assert a.evidence_weight == b.evidence_weight
    assert a.evidence_weight == pytest.approx(Infotaxis.evidence_weight / math.sqrt(2.0), rel=1e-15)
    assert sum(m.hits for _, m in flight.published["uav1"] + flight.published["uav2"]) > 0
    held_a, held_b = held(flight, "uav1"), held(flight, "uav2")
    assert a.belief is not None and b.belief is not None
    np.testing.assert_allclose(a.belief, product_posterior(a, held_a), rtol=1e-9, atol=0.0)
    np.testing.assert_allclose(b.belief, product_posterior(b, held_b), rtol=1e-9, atol=0.0)
    # each lacks only the other's newest; with it, both hold the posterior of every step
    only_b = [m for m in held_b if m not in held_a]
    only_a = [m for m in held_a if m not in held_b]
    assert only_a and only_b
    full_a, full_b = product_posterior(a, only_b, a.belief), product_posterior(b, only_a, b.belief)
    np.testing.assert_allclose(full_a, full_b, rtol=1e-9, atol=0.0)


def test_members_with_the_concentration_likelihood_hold_the_product_of_theirs() -> None:
    """The same with ``likelihood = "concentration"``: each member shares the class of its
    step's mean reading (in ``hits``), and its posterior is the product of every held
    observation's concentration likelihood."""
    flight = fly(pair(RadioSpec()), 8.0, ConcentrationMember)
    a, b = flight.members["uav1"], flight.members["uav2"]
    assert a.concentration and a.n_classes == Infotaxis.concentration_classes
    assert a.evidence_weight == pytest.approx(
        Infotaxis.concentration_evidence_weight / math.sqrt(2.0), rel=1e-15
    )
    classes = {m.hits for _, m in flight.published["uav1"] + flight.published["uav2"]}
    assert 0 in classes and len(classes) > 1  # blanks and readings over the level
    for vid, member in (("uav1", a), ("uav2", b)):
        assert member.belief is not None
        np.testing.assert_allclose(
            member.belief, product_posterior(member, held(flight, vid)), rtol=1e-9, atol=0.0
        )


def test_a_lost_observation_is_missing_and_a_late_one_is_applied_when_it_arrives() -> None:
    latency = 30  # 1.5 s: longer than a step
    flight = fly(pair(RadioSpec(loss=0.5, latency_ticks=latency)), 10.0)
    a = flight.members["uav1"]
    assert a.belief is not None
    own_steps = [tick for tick, _ in flight.published["uav1"]]
    last = own_steps[-1]
    arrived = {m for _, m in flight.received["uav1"]}
    sent = [(tick, m) for tick, m in flight.published["uav2"] if tick + 1 + latency <= last]
    lost = [m for _, m in sent if m not in arrived]
    assert lost and len(lost) < len(sent)
    # delivered late: after at least one of the receiver's steps that followed its sending
    late = [tick for tick, _ in flight.received["uav1"] if tick <= last]
    assert late and all(any(tick - latency <= s < tick for s in own_steps) for tick in late)
    expected = product_posterior(a, held(flight, "uav1"))
    np.testing.assert_allclose(a.belief, expected, rtol=1e-9, atol=0.0)
    with_lost = product_posterior(a, lost, expected)
    assert np.max(np.abs(with_lost - a.belief) / a.belief) > 1e-3


def test_a_swarm_of_three_flies_a_kinematic_bench_episode() -> None:
    opts = make_options(["coop_infotaxis"], ["meander_low"], ["ideal"], runs=1, seed=1000,
                        vehicles="3", time_limit_s=30.0, jobs=1)  # fmt: skip
    outcomes = [o for o in run_all(opts) if o.spec.algorithm == "coop_infotaxis"]
    (row,) = [r for r in rows_of(opts, outcomes) if r["algorithm"] == "coop_infotaxis"]
    assert row["vehicles"] == 3
    (outcome,) = outcomes
    assert len(outcome.trajectories) == 3
    for track in outcome.trajectories:  # every member flew its own steps of 2 m
        assert max(math.dist(track[0], p) for p in track) > 4.0
    assert outcome.total_path_m > 3 * 10.0
    assert outcome.closest_approach_m is not None and outcome.closest_approach_m > 0.5


def test_the_message_is_small_and_the_registry_names_the_swarm() -> None:
    algo = BUILTIN_ALGORITHMS["coop_infotaxis"]
    assert algo.vehicles == 3 and algo.start_spacing_m == 4.0
    message = Observation(12.345678, -3.21, 1.05, 3, 5.99, 0.01, 14.345678, -3.21)
    # msgpack: an array header, 7 doubles of 9 bytes and a small int of 1
    assert len(msgspec.msgpack.encode(message)) == 1 + 7 * 9 + 1 <= IDEAL.radio.max_message_bytes
    assert CooperativeInfotaxis.talks
