"""Holding the clock (docs/physics.md, "Restarts: the clock waits") with a fake clock and a
real barrier: how long a tick waits for a process that leaves, by the documented rules."""

from __future__ import annotations

from sim_world.holds import BACKFILL_TICKS, Holds, UnreachableGrace
from sim_world.lockstep import Lockstep
from tests.support.fake_clock import FakeClock

TIMEOUT_S = 0.5  # time.participant_timeout_s: also the wait for the launcher's word
GRACE_S = 30.0  # time.restart_grace_s
REPUBLISH_S = 0.1


def setup(grace_s: float = GRACE_S) -> tuple[Holds, Lockstep, FakeClock]:
    clock = FakeClock()
    barrier = Lockstep(["a", "b"], timeout_s=TIMEOUT_S, clock=clock)
    for vid in ("a", "b"):
        barrier.joined(vid)
    barrier.start()
    barrier.begin(0)
    return Holds(grace_s, TIMEOUT_S, clock, REPUBLISH_S), barrier, clock


def test_without_a_grace_a_participant_that_leaves_is_dropped_at_once() -> None:
    holds, barrier, _ = setup(grace_s=0.0)
    assert not holds.enabled
    holds.leave(barrier, "a")
    barrier.receive("b", 0, [0.5])
    assert barrier.complete()
    assert barrier.active == {"b"}


def test_a_participant_that_leaves_is_held_until_the_deadline_then_the_grace() -> None:
    holds, barrier, clock = setup()
    holds.leave(barrier, "a")
    assert barrier.held == {"a"} and not barrier.complete()
    assert barrier.remaining_s() == TIMEOUT_S  # time for the launcher's word
    clock.now += 0.25
    assert holds.restart_notice(barrier, ["a"], restarting=True, delay_s=2.0) == ["a"]
    assert barrier.remaining_s() == 2.0 + GRACE_S  # its backoff and the grace, from the notice
    barrier.joined("a")  # the new process's token, and its answer to the held tick
    barrier.receive("a", 0, [0.1])
    barrier.receive("b", 0, [0.1])
    assert barrier.complete() and barrier.held == frozenset()


def test_a_participant_that_will_not_be_restarted_is_dropped_at_the_notice() -> None:
    holds, barrier, _ = setup()
    holds.leave(barrier, "a")
    assert holds.restart_notice(barrier, ["a"], restarting=False, delay_s=0.0) == ["a"]
    barrier.receive("b", 0, [0.2])
    assert barrier.complete() and barrier.active == {"b"}


def test_whoever_leaves_with_the_router_is_held_for_the_grace_without_a_notice() -> None:
    holds, barrier, clock = setup()
    holds.leave(barrier, "a")  # left just before the router's token
    assert not holds.router(barrier, alive=False, tick=7)
    assert barrier.remaining_s() == GRACE_S  # extended to the grace with the router's departure
    clock.now += 10.0
    holds.leave(barrier, "b")
    assert barrier.held == {"a", "b"}
    assert barrier.remaining_s() == GRACE_S - 10.0  # to the router's grace, not a fresh one
    assert holds.router(barrier, alive=True, tick=7)  # it was away
    assert not holds.router(barrier, alive=True, tick=7)


def test_after_the_router_is_back_a_departure_waits_for_the_launchers_word_again() -> None:
    holds, barrier, _ = setup()
    holds.router(barrier, alive=False, tick=0)
    holds.router(barrier, alive=True, tick=0)
    holds.leave(barrier, "a")
    assert barrier.remaining_s() == TIMEOUT_S


def test_the_held_tick_goes_with_its_states_only_on_the_routers_outage_tick() -> None:
    holds, barrier, _ = setup()
    assert not holds.resend_states(7)
    holds.router(barrier, alive=False, tick=7)
    assert holds.resend_states(7) and not holds.resend_states(8)


def test_the_held_tick_is_re_sent_every_republish_period() -> None:
    holds, _, clock = setup()
    assert holds.republish_due()
    clock.now += 0.0625  # binary fractions: the sums are exact
    assert not holds.republish_due()
    clock.now += 0.0625
    assert holds.republish_due()
    assert not holds.republish_due()


def test_the_recorder_is_waited_for_up_to_the_word_or_the_restart_grace() -> None:
    holds, _, clock = setup()
    holds.recorder_presence(alive=False)
    assert holds.recorder_lost
    holds.begin_recorder_wait()
    assert holds.recorder_wait_s() == TIMEOUT_S
    holds.recorder_notice(restarting=True, delay_s=1.0)
    assert holds.recorder_wait_s() == 1.0 + GRACE_S
    clock.now += 3.0
    holds.recorder_presence(alive=True)
    assert holds.recorder_wait_s() is None  # back
    assert holds.end_recorder_wait()
    assert not holds.recorder_lost


def test_a_recorder_that_is_not_restarted_is_not_waited_for() -> None:
    holds, _, clock = setup()
    holds.recorder_presence(alive=False)
    holds.recorder_notice(restarting=False, delay_s=0.0)
    assert not holds.recorder_lost
    holds.begin_recorder_wait()
    clock.now += TIMEOUT_S
    assert holds.recorder_wait_s() == 0.0
    assert not holds.end_recorder_wait()


def test_the_router_leaving_holds_the_recorder_for_the_grace() -> None:
    holds, barrier, _ = setup()
    holds.router(barrier, alive=False, tick=3)
    holds.recorder_presence(alive=False)
    holds.begin_recorder_wait()
    assert holds.recorder_wait_s() == GRACE_S


def test_the_last_ticks_are_kept_for_a_backfill_only_while_holds_are_on() -> None:
    holds, _, _ = setup()
    for k in range(BACKFILL_TICKS + 44):
        holds.remember([("tick", bytes([k % 256]))])
    assert len(holds.recent) == 256
    assert holds.recent[0] == [("tick", bytes([44]))]
    off, _, _ = setup(grace_s=0.0)
    off.remember([("tick", b"\x00")])
    assert len(off.recent) == 0


def test_an_unreachable_grace_holds_a_silent_tick_once_then_drops_at_the_grace() -> None:
    """time.unreachable_grace_s = 10 with a 0.5 s deadline: the tick waits 10 s in all for a
    participant whose token never left (a partition), then drops it; answered in time, nobody
    is dropped and the hold ends."""
    _, barrier, clock = setup()
    silent = UnreachableGrace(10.0, clock)
    barrier.receive("b", 0, [0.5])
    clock.now += TIMEOUT_S
    assert barrier.remaining_s() <= 0.0
    assert silent.hold(barrier, 0) and silent.holding(0)
    assert barrier.remaining_s() == 10.0 - TIMEOUT_S
    assert not silent.hold(barrier, 0)  # once per tick
    clock.now += 10.0 - TIMEOUT_S
    assert barrier.remaining_s() <= 0.0 and barrier.expire() == ["a"]
    assert silent.waited_s(0, TIMEOUT_S) == 10.0
    silent.dropped()
    assert not silent.holding(0) and silent.waited_s(0, TIMEOUT_S) == TIMEOUT_S


def test_without_an_unreachable_grace_the_deadline_drops() -> None:
    _, barrier, clock = setup()
    silent = UnreachableGrace(0.0, clock)
    clock.now += TIMEOUT_S
    assert not silent.hold(barrier, 0)
    assert sorted(barrier.expire()) == ["a", "b"]


def test_a_silent_tick_answered_within_the_grace_goes_on_with_everyone() -> None:
    _, barrier, clock = setup()
    silent = UnreachableGrace(10.0, clock)
    clock.now += TIMEOUT_S
    assert silent.hold(barrier, 0)
    clock.now += 4.0
    barrier.receive("a", 0, [0.5])
    barrier.receive("b", 0, [0.5])
    assert barrier.complete() and barrier.active == {"a", "b"}
    silent.report_back(barrier, 0)
    assert not silent.holding(0)
