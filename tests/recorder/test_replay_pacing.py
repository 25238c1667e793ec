"""Replay's schedule from publish times stamped by hosts whose clocks disagree (the recorder's
receive times, one clock, tell them apart): docs/reliability.md, "Clocks of the hosts"."""

from __future__ import annotations

import pytest

from recorder.replay import Pacing

S = 1_000_000_000  # ns per s
T0 = 1_790_000_000 * S  # some wall time


def schedule(messages: list[tuple[float, float]]) -> list[float]:
    """Due times of (publish offset s, receive offset s) messages, in order."""
    pacing = Pacing()
    return [pacing.due_s(T0 + round(p * S), T0 + round(r * S)) for p, r in messages]


def test_one_clock_keeps_the_publish_spacing_pauses_and_receive_jitter_aside() -> None:
    # 10 Hz with a 2 s pause; the recorder got some of them late (a stall, then a burst)
    publish = [0.0, 0.1, 0.2, 2.2, 2.3, 2.4, 2.5]
    receive = [0.001, 0.101, 0.45, 2.46, 2.461, 2.401 + 0.1, 2.501]
    assert schedule(list(zip(publish, receive, strict=True))) == pytest.approx(publish)


@pytest.mark.parametrize("recorder_offset_s", [-0.4, 0.4])
def test_a_recorder_within_the_bound_of_the_publishers_keeps_their_spacing(
    recorder_offset_s: float,
) -> None:
    publish = [0.0, 0.1, 0.2, 0.3]
    got = schedule([(p, p + recorder_offset_s + 0.001) for p in publish])
    assert got == pytest.approx(publish)


def test_a_first_message_from_a_host_5_s_behind_does_not_hold_the_others_back() -> None:
    # host B's clock 5 s behind host A's (and the recorder's); B publishes first, then A and B
    # alternate at 10 Hz: in real (receive) time message k comes at k * 0.1 s
    behind = 5.0
    messages = []
    for k in range(8):
        host_b = k % 2 == 0
        messages.append((k * 0.1 - (behind if host_b else 0.0), k * 0.1 + 0.001))
    got = schedule(messages)
    # A's messages are due at their real times (B's own, earlier, go out at once after the
    # message before them: never later than their real times)
    for k, due in enumerate(got):
        if k % 2 == 1:
            assert due == pytest.approx(k * 0.1, abs=1e-6), (k, got)
        else:
            assert due <= k * 0.1 + 1e-6, (k, got)
    # without the recorder's clock the first of A's would wait the 5 s
    assert max(got) < 1.0, got


def test_a_host_5_s_ahead_first_keeps_its_spacing_and_the_others_go_in_order() -> None:
    # host A 5 s ahead publishes first, then only host B (on time) for a while
    messages = [(5.0, 0.001)] + [(k * 0.1, k * 0.1 + 0.001) for k in range(1, 6)]
    got = schedule(messages)
    assert got[0] == 0.0
    assert all(due <= k * 0.1 + 1e-6 for k, due in enumerate(got)), got
