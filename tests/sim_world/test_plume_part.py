"""The plume's part of the lockstep (docs/physics.md, "The plume's part") by direct calls:
several services are one participant; tick k + 1 carries the answer to sensor tick k."""

from __future__ import annotations

from sim_world.plume_part import PlumeParticipation, decode_answer, is_plume
from swarmbus.codec import encode
from swarmbus.messages import FieldSample, PlumeSample


def answer(tick: int, values: list[float] | None) -> FieldSample:
    return FieldSample(tick=tick, sim_time_s=tick / 120.0, values_g_m3=values)


def test_plume_tokens_are_plume_and_plume_dash_anything() -> None:
    assert is_plume("plume") and is_plume("plume-2") and is_plume("plume-east")
    assert not is_plume("plumes") and not is_plume("autopilot-plume") and not is_plume("")


def test_several_services_are_one_participant_present_while_any_is() -> None:
    part = PlumeParticipation()
    assert part.presence("plume", True)  # the participant arrives
    assert not part.presence("plume-2", True)
    assert not part.presence("plume", False)  # plume-2 is still there
    assert not part.presence("plume", False)  # a repeated departure changes nothing
    assert part.presence("plume-2", False)  # the last one went


def test_the_next_tick_carries_the_answer_to_a_sensor_tick_once() -> None:
    part = PlumeParticipation()
    assert part.published(True, 3) is None  # tick 12 waits for the plume
    part.answered(answer(12, [0.0, 1.5, 2.25]))
    part.take(12)
    assert part.published(False, 3) == PlumeSample(tick=12, values_g_m3=[0.0, 1.5, 2.25])
    part.take(13)
    assert part.published(False, 3) is None  # tick 14 carries nothing: spent on tick 13


def test_a_sensor_tick_without_an_answer_carries_unavailable_values() -> None:
    part = PlumeParticipation()
    part.published(True, 2)
    part.take(24)  # dropped after its deadline: no answer
    assert part.carried == PlumeSample(tick=24, values_g_m3=None)


def test_an_answer_that_does_not_fit_the_ticks_states_is_unavailable() -> None:
    part = PlumeParticipation()
    part.published(True, 3)
    part.answered(answer(36, [1.0, 2.0]))  # two points for three states
    part.take(36)
    assert part.carried == PlumeSample(tick=36, values_g_m3=None)


def test_an_answer_for_a_tick_that_did_not_wait_is_dropped() -> None:
    part = PlumeParticipation()
    part.published(False, 2)
    part.answered(answer(5, [1.0, 2.0]))
    part.take(5)
    assert part.carried is None
    part.published(True, 2)  # the next sensor tick: the stale answer is gone
    part.take(12)
    assert part.carried == PlumeSample(tick=12, values_g_m3=None)


def test_an_answer_that_does_not_decode_is_none() -> None:
    good = answer(12, [0.5])
    assert decode_answer(encode(good), "k") == good
    assert decode_answer(b"\x01garbage", "k") is None
