"""What a vehicle learns of its peers through the radio: states, samples and behaviours'
messages, with the default link unchanged, latency, range, loss and the size limit."""

from __future__ import annotations

import sys
import types
from dataclasses import replace
from typing import Any, ClassVar

import msgspec
import pytest

from agents.peer_link import MESSAGE_INDEX, PeerLink, RadioError, Received
from plumeswarm.experiments.fused import FusedRunner
from plumeswarm.gsl.episode import EpisodeSpec, kinematic_episode
from swarmbus.messages import Arm, FlightMode, PeerReading, SetMode, Setpoint, VehicleState
from swarmbus.radio import Radio, RadioSpec
from swarmbus.scenario import Scenario, VehicleSpec
from tests.support.messages_samples import reading, vehicle_state
from tests.support.procs import REPO

IDS = ("uav1", "uav2", "uav3")


class Hit(msgspec.Struct, frozen=True):
    x_m: float
    y_m: float
    t_s: float


def scenario(radio: RadioSpec | None = None, seed: int = 11) -> Scenario:
    radio = radio or RadioSpec()
    s = Scenario(vehicles=[VehicleSpec(id=v) for v in IDS])
    return msgspec.structs.replace(
        s, radio=radio, world=msgspec.structs.replace(s.world, seed=seed)
    )


def states_at(tick: int, xs: tuple[float, ...] = (0.0, 10.0, 20.0)) -> list[VehicleState]:
    return [vehicle_state(v, tick, (x, 0.0, 10.0)) for v, x in zip(IDS, xs, strict=True)]


def fly(link: PeerLink, ticks: int, xs: tuple[float, ...] = (0.0, 10.0, 20.0)) -> list:
    """Each tick: every vehicle's peers (vehicle ids and the tick of their state), and uav1
    publishing one Hit; what each inbox held."""
    seen = []
    for tick in range(ticks):
        states = states_at(tick, xs)
        link.before_step(tick)
        peers = link.peers(tick, states)
        inboxes = {v: list(link.mailboxes[v].inbox) for v in IDS}
        link.mailboxes["uav1"].publish(Hit(x_m=1.0, y_m=2.0, t_s=tick * 0.1))
        link.after_step(tick, states)
        seen.append(([[(p.vehicle_id, p.tick) for p in ps] for ps in peers], inboxes))
    return seen


def test_the_default_link_delivers_every_peer_unchanged_and_messages_next_tick() -> None:
    link = PeerLink(scenario())
    states = states_at(5)
    assert link.peers(5, states) == [
        [states[1], states[2]],
        [states[0], states[2]],
        [states[0], states[1]],
    ]
    own = [reading(v, 0.5, s.position_enu_m, 0.01, [PeerReading(vehicle_id="x",
           position_enu_m=(0.0, 0.0, 0.0), true_g_m3=0.2)]) for v, s in zip(IDS, states,
           strict=True)]  # fmt: skip
    assert link.readings(5, states, own) == own
    for tick, (_, inboxes) in enumerate(fly(PeerLink(scenario()), 4)):
        assert inboxes["uav1"] == []  # never to itself
        expected = (
            [] if tick == 0 else [Received("uav1", tick - 1, Hit(1.0, 2.0, (tick - 1) * 0.1))]
        )
        assert inboxes["uav2"] == inboxes["uav3"] == expected


@pytest.mark.parametrize("k", [1, 4])
def test_latency_delays_states_and_messages_by_exactly_k_ticks(k: int) -> None:
    seen = fly(PeerLink(scenario(RadioSpec(latency_ticks=k))), 10)
    for tick, (peers, inboxes) in enumerate(seen):
        if tick < k:
            assert peers == [[], [], []]
        else:
            assert peers[0] == [("uav2", tick - k), ("uav3", tick - k)]
        sent = [m.sent_tick for m in inboxes["uav2"]]
        assert sent == ([tick - 1 - k] if tick >= 1 + k else [])


def test_range_cuts_the_far_peer() -> None:
    seen = fly(PeerLink(scenario(RadioSpec(range_m=15.0))), 3, xs=(0.0, 10.0, 20.0))
    peers, inboxes = seen[2]
    assert peers == [[("uav2", 2)], [("uav1", 2), ("uav3", 2)], [("uav2", 2)]]
    assert len(inboxes["uav2"]) == 1 and inboxes["uav3"] == []


def test_a_lost_state_leaves_the_last_one_received() -> None:
    """With loss, a receiver's peer state is the newest one the radio delivered, and each
    state's fate is the radio's decision for (tick, sender, receiver, index 0)."""
    spec = RadioSpec(loss=0.5)
    radio = Radio(spec, seed=11)
    seen = fly(PeerLink(scenario(spec)), 40)
    for tick, (peers, _) in enumerate(seen):
        for receiver, got in zip(IDS, peers, strict=True):
            for sender in IDS:
                if sender == receiver:
                    continue
                delivered = [t for t in range(tick + 1) if radio.delivers(t, sender, receiver)]
                expected = (sender, delivered[-1]) if delivered else None
                assert next((p for p in got if p[0] == sender), None) == expected


def test_peer_samples_arrive_with_the_next_own_reading() -> None:
    link = PeerLink(scenario(RadioSpec(latency_ticks=2)))
    got = []
    for tick in range(6):
        states = states_at(tick)
        link.before_step(tick)
        link.peers(tick, states)
        own = [reading(v, tick, s.position_enu_m, 0.001 * (tick + 1)) for v, s in
               zip(IDS, states, strict=True)]  # fmt: skip
        got.append(link.readings(tick, states, own)[0].peers)
    assert got[0] == got[1] == []
    assert got[4] == [
        PeerReading(vehicle_id="uav2", position_enu_m=(10.0, 0.0, 10.0), true_g_m3=0.003),
        PeerReading(vehicle_id="uav3", position_enu_m=(20.0, 0.0, 10.0), true_g_m3=0.003),
    ]


def test_a_message_over_the_limit_is_refused_when_published() -> None:
    link = PeerLink(scenario(RadioSpec(max_message_bytes=8)))
    with pytest.raises(RadioError, match=r"radio\.max_message_bytes"):
        link.mailboxes["uav1"].publish(Hit(1.0, 2.0, 3.0))
    with pytest.raises(RadioError, match=r"msgspec\.Struct"):
        link.mailboxes["uav1"].publish({"x": 1})  # type: ignore[arg-type]


def test_a_lossy_radio_changes_what_the_swarm_sees_and_the_same_spec_repeats() -> None:
    base = EpisodeSpec("gradient_swarm", "steady_gaussian", "ideal", run=0, seed=1000,
                       time_limit_s=20.0)  # fmt: skip
    lossy = replace(base, overrides=(("radio.loss", 0.9),))
    a, b, c = kinematic_episode(base), kinematic_episode(lossy), kinematic_episode(lossy)
    assert b.estimate_xy == c.estimate_xy and b.path_length_m == c.path_length_m
    assert a.estimate_xy != b.estimate_xy


def test_the_docs_example_behaviour_talks_to_its_peers_in_an_episode() -> None:
    """docs/agents.md's Gossip, flown by three vehicles: finds are published and heard."""
    text = (REPO / "docs" / "agents.md").read_text()
    code = next(b for b in text.split("```python\n")[1:] if "class Gossip" in b).split("```")[0]
    module = types.ModuleType("gossip_example")
    sys.modules["gossip_example"] = module
    try:
        exec(compile(code, "docs/agents.md", "exec"), module.__dict__)
        heard: list[Received] = []

        class Listening(module.Gossip):  # type: ignore[name-defined,misc]
            def seek(self, step: Any) -> Any:
                heard.extend(step.inbox)
                return super().seek(step)

        setattr(module, "Listening", Listening)  # noqa: B010
        spec = EpisodeSpec("gossip", "steady_gaussian", "ideal", run=3, seed=1000,
                           time_limit_s=20.0, behavior="gossip_example:Listening",
                           vehicles=3)  # fmt: skip
        kinematic_episode(spec)
    finally:
        del sys.modules["gossip_example"]
    assert heard, "no vehicle heard a peer's detection"
    assert {type(r.message).__name__ for r in heard} == {"Detection"}
    assert len({r.sender for r in heard}) >= 2


class Chatter:
    """A behaviour that holds where it is, says its tick each step, and keeps what it saw."""

    seen: ClassVar[dict[str, list[tuple[int, list[tuple[str, int]], list[Received]]]]] = {}

    def __init__(self, ctx: Any) -> None:
        self.vid, self.mailbox = ctx.vehicle_id, ctx.mailbox
        Chatter.seen[self.vid] = []

    def step(self, own: VehicleState, peers: Any, readings: Any) -> Setpoint:
        inbox = list(self.mailbox.inbox)
        Chatter.seen[self.vid].append((own.tick, [(p.vehicle_id, p.tick) for p in peers], inbox))
        self.mailbox.publish(Tick(tick=own.tick))
        return Setpoint(position_enu_m=own.position_enu_m)


class Tick(msgspec.Struct, frozen=True):
    tick: int


def test_the_fused_runner_hands_peers_and_messages_over_the_radio() -> None:
    """Three vehicles armed in offboard with a behaviour: each step's peers are the newest
    states the radio delivered (its own decisions, asked here independently) and each
    message arrives 1 + latency ticks after the step that published it, if delivered."""
    spec = RadioSpec(loss=0.4, latency_ticks=3)
    base = scenario(spec, seed=4)
    behavior = "tests.agents.test_peer_link:Chatter"
    sc = msgspec.structs.replace(
        base,
        vehicles=[
            VehicleSpec(id=v, behavior=behavior, spawn_enu_m=(5.0 * i, 0.0, 0.0))
            for i, v in enumerate(IDS)
        ],
    )
    with FusedRunner(sc) as runner:
        for vid in IDS:
            assert runner.command(vid, Arm()).accepted
            assert runner.command(vid, SetMode(mode=FlightMode.OFFBOARD)).accepted
        runner.step(30)
    radio = Radio(spec, seed=4)
    for receiver in IDS:
        steps = Chatter.seen[receiver]
        assert [t for t, _, _ in steps] == list(range(1, 31))
        for tick, peers, inbox in steps:
            expected_peers = []
            for sender in IDS:
                sent = [
                    t
                    for t in range(tick - spec.latency_ticks + 1)
                    if sender != receiver and radio.delivers(t, sender, receiver)
                ]
                if sent:
                    expected_peers.append((sender, sent[-1]))
            assert peers == expected_peers
            sent_tick = tick - 1 - spec.latency_ticks
            expected_inbox = [
                (s, sent_tick)
                for s in IDS
                if s != receiver
                and sent_tick >= 1
                and radio.delivers(sent_tick, s, receiver, MESSAGE_INDEX)
            ]
            assert sorted((r.sender, r.sent_tick) for r in inbox) == expected_inbox
            assert all(r.message == Tick(tick=r.sent_tick) for r in inbox)


def test_a_link_restored_from_its_snapshot_carries_on_with_the_same_deliveries() -> None:
    """An autopilot's checkpoint holds its link: restored into a new link between a step and
    the sending of its messages (where the process saves it), the rest of the run hears the
    same peers, samples and messages, counted the same, as a run never interrupted."""
    radio = RadioSpec(loss=0.3, latency_ticks=4, range_m=15.0)

    def run(ticks: int, restart_at: int | None) -> tuple[list, dict]:
        link = PeerLink(scenario(radio))
        seen = []
        for tick in range(ticks):
            states = states_at(tick, (0.0, 10.0 + tick * 0.05, 20.0))
            link.before_step(tick)
            peers = link.peers(tick, states)
            samples = [reading(v, tick * 0.1, s.position_enu_m, 0.1 * k)
                       for k, (v, s) in enumerate(zip(IDS, states, strict=True))]  # fmt: skip
            heard = link.readings(tick, states, samples)
            inboxes = {v: list(link.mailboxes[v].inbox) for v in IDS}
            link.mailboxes["uav1"].publish(Hit(x_m=1.0, y_m=2.0, t_s=tick * 0.1))
            link.mailboxes["uav3"].publish(Hit(x_m=3.0, y_m=4.0, t_s=tick * 0.1))
            if tick == restart_at:
                fresh = PeerLink(scenario(radio))
                fresh.restore(link.snapshot())
                link = fresh
            link.after_step(tick, states)
            seen.append(
                (
                    [[(p.vehicle_id, p.tick) for p in ps] for ps in peers],
                    [[p.vehicle_id for p in r.peers] for r in heard],
                    inboxes,
                )
            )
        counts = {k: (c.delivered, c.dropped) for k, c in link.counts.items()}
        return seen, counts

    whole, whole_counts = run(60, None)
    restarted, restarted_counts = run(60, 25)
    assert restarted == whole and restarted_counts == whole_counts
    # not vacuous: messages were in flight at the restart, and some were lost
    assert any(inbox for _, _, inboxes in whole[26:30] for inbox in inboxes.values())
    assert any(c[1] for c in whole_counts.values())
