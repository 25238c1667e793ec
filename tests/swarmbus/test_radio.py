"""The radio between vehicles: loss at its rate, decisions independent of who asks and in what
order, range, the size limit, and the scenario's ``[radio]`` section."""

from __future__ import annotations

import math
import random

import pytest

from swarmbus.radio import DEFAULT_MAX_MESSAGE_BYTES, Radio, RadioError, RadioSpec
from swarmbus.scenario import ScenarioError, parse_scenario

VEHICLES = """
[[vehicles]]
id = "uav1"
"""


def _queries(n: int) -> list[tuple[int, str, str, int]]:
    ids = [f"uav{i}" for i in range(1, 6)]
    return [
        (tick, a, b, index)
        for tick in range(n)
        for a in ids
        for b in ids
        if a != b
        for index in range(3)
    ][: n * 60]


@pytest.mark.parametrize("loss", [0.05, 0.2, 0.5, 0.9])
def test_the_loss_rate_is_p_within_a_binomial_bound(loss: float) -> None:
    radio = Radio(RadioSpec(loss=loss), seed=1234)
    queries = _queries(400)
    n = len(queries)
    lost = sum(not radio.delivers(*q) for q in queries)
    # 4.5 standard deviations of Binomial(n, p): a correct model fails this once in ~150 000.
    assert abs(lost - n * loss) <= 4.5 * math.sqrt(n * loss * (1.0 - loss))


def test_losses_on_two_links_and_two_ticks_are_independent() -> None:
    """P(both lost) is p² for the two directions of a link and for consecutive ticks."""
    p = 0.5
    radio = Radio(RadioSpec(loss=p), seed=7)
    n = 20_000
    both_ways = sum(
        not radio.delivers(t, "a", "b") and not radio.delivers(t, "b", "a") for t in range(n)
    )
    next_tick = sum(
        not radio.delivers(t, "a", "b") and not radio.delivers(t + 1, "a", "b") for t in range(n)
    )
    bound = 4.5 * math.sqrt(n * p * p * (1 - p * p))
    assert abs(both_ways - n * p * p) <= bound
    assert abs(next_tick - n * p * p) <= bound


def test_decisions_do_not_depend_on_the_order_or_the_asker() -> None:
    spec = RadioSpec(loss=0.3)
    queries = _queries(50)
    first = {q: Radio(spec, seed=99).delivers(*q) for q in queries}
    shuffled = list(queries)
    random.Random(5).shuffle(shuffled)
    other = Radio(spec, seed=99)  # a second asker, another order
    second = {q: other.delivers(*q) for q in shuffled}
    assert first == second
    assert 0 < sum(first.values()) < len(first)  # the decisions are not all one way
    # a different world seed decides differently
    third = {q: Radio(spec, seed=100).delivers(*q) for q in queries}
    assert third != first


def test_range_cuts_the_link_beyond_range_m() -> None:
    radio = Radio(RadioSpec(range_m=50.0), seed=0)
    here = (0.0, 0.0, 10.0)
    assert radio.delivers(3, "a", "b", 0, here, (30.0, 40.0, 10.0))  # 50 m: in range
    assert not radio.delivers(3, "a", "b", 0, here, (30.0, 40.1, 10.0))
    assert not radio.delivers(3, "a", "b", 0, here, (0.0, 0.0, 60.5))  # vertical counts


def test_latency_delays_arrival_by_exactly_k_ticks() -> None:
    assert Radio(RadioSpec(latency_ticks=7), seed=0).arrival_tick(100) == 107
    assert Radio(RadioSpec(), seed=0).arrival_tick(100) == 100


def test_the_default_is_a_perfect_link() -> None:
    radio = Radio(RadioSpec(), seed=3)
    assert radio.perfect
    far = (1e6, 0.0, 10.0)
    assert all(radio.delivers(*q, (0.0, 0.0, 0.0), far) for q in _queries(20))
    assert RadioSpec().max_message_bytes == DEFAULT_MAX_MESSAGE_BYTES == 255
    assert not RadioSpec(loss=0.1).perfect
    assert not RadioSpec(latency_ticks=1).perfect
    assert not RadioSpec(range_m=100.0).perfect


def test_a_message_over_the_size_limit_is_refused_in_one_line() -> None:
    radio = Radio(RadioSpec(max_message_bytes=16), seed=0)
    radio.check_size(b"x" * 16)
    with pytest.raises(RadioError, match=r"radio.max_message_bytes: .* 17 bytes .* 16 bytes"):
        radio.check_size(b"x" * 17)


def test_the_scenario_reads_its_radio_section() -> None:
    scenario = parse_scenario(
        "[radio]\nrange_m = 80.0\nloss = 0.2\nlatency_ticks = 12\n" + VEHICLES, "radio.toml"
    )
    assert scenario.radio == RadioSpec(range_m=80.0, loss=0.2, latency_ticks=12)
    assert parse_scenario(VEHICLES, "plain.toml").radio.perfect
    with pytest.raises(ScenarioError, match=r"radio.loss"):
        parse_scenario("[radio]\nloss = 1.5\n" + VEHICLES, "bad.toml")
    with pytest.raises(ScenarioError, match=r"radio.*bandwidth"):
        parse_scenario("[radio]\nbandwidth = 3\n" + VEHICLES, "bad.toml")
