"""The lockstep barrier's logic with a fake clock (no bus, no sleeping)."""

from __future__ import annotations

from sim_world.lockstep import Lockstep, participant_of
from tests.support.fake_clock import FakeClock


def barrier(*present: str) -> tuple[Lockstep, FakeClock]:
    clock = FakeClock()
    ls = Lockstep(["a", "b", "c"], timeout_s=0.5, clock=clock)
    for vid in present:
        ls.joined(vid)
    return ls, clock


def begun(tick: int, *present: str) -> tuple[Lockstep, FakeClock]:
    """A started :func:`barrier` with ``present`` joined, at tick ``tick``."""
    ls, clock = barrier(*present)
    ls.start()
    ls.begin(tick)
    return ls, clock


def answered(ls: Lockstep, tick: int, *vids: str) -> None:
    """Each of ``vids`` answers ``tick`` (a zero command)."""
    for vid in vids:
        ls.receive(vid, tick, [0.0])


def test_participant_tokens_name_exactly_one_known_vehicle() -> None:
    ids = ("uav1", "uav-2")
    assert participant_of("autopilot-uav1", ids) == "uav1"
    assert participant_of("autopilot-uav-2", ids) == "uav-2"
    assert participant_of("autopilot-uav1-uav-2", ids) is None
    assert participant_of("physics", ids) is None
    assert participant_of("autopilot-ghost", ids) is None


def test_startup_names_who_is_missing() -> None:
    ls, _ = barrier("b")
    assert ls.missing_tokens() == ["a", "c"]
    assert not ls.joined("zzz")


def test_tick_completes_only_when_every_active_participant_answered() -> None:
    ls, _ = begun(0, "a", "b")
    assert not ls.complete()
    assert ls.receive("a", 0, [0.1])
    assert not ls.complete() and ls.missing() == ["b"]
    assert not ls.receive("b", 1, [0.2])  # a future tick does not count
    assert ls.receive("b", 0, [0.2])
    assert ls.complete()
    assert ls.commands() == {"a": [0.1], "b": [0.2]}
    ls.begin(1)
    assert not ls.complete() and ls.commands() == {}


def test_stale_and_tokenless_commands_are_ignored() -> None:
    ls, _ = begun(5, "a")
    assert not ls.receive("a", 4, [0.0])
    assert not ls.receive("c", 5, [0.0])  # no token
    assert not ls.complete()


def test_a_silent_participant_is_dropped_at_the_deadline_not_before() -> None:
    ls, clock = begun(3, "a", "b")
    ls.receive("a", 3, [0.3])
    clock.now += 0.49
    assert ls.expire() == []
    clock.now += 0.02
    assert ls.remaining_s() < 0
    assert ls.expire() == ["b"]
    assert ls.active == {"a"} and ls.complete()
    ls.begin(4)
    ls.receive("a", 4, [0.4])
    assert ls.complete()  # the world goes on without b


def test_a_dropped_participant_rejoins_when_it_answers_a_tick_since_its_drop() -> None:
    ls, clock = begun(3, "a", "b")
    clock.now += 1.0
    assert ls.expire() == ["a", "b"]
    ls.begin(4)
    assert not ls.receive("b", 2, [0.0])  # in flight from before the drop
    assert "b" not in ls.active
    assert not ls.receive("b", 3, [0.0])  # late answer to the tick it missed: back in ...
    assert "b" in ls.active
    assert not ls.complete()  # ... and waited for from this tick on
    assert ls.receive("b", 4, [0.5])
    assert ls.complete()


def test_a_late_joiner_is_admitted_by_its_first_answer() -> None:
    ls, _ = begun(10, "a")
    ls.joined("c")
    assert ls.present == {"a", "c"} and ls.active == {"a"}
    ls.receive("a", 10, [0.1])
    assert ls.complete()  # not waited for before it answers
    assert ls.receive("c", 10, [0.9])
    assert ls.active == {"a", "c"}
    ls.begin(11)
    ls.receive("a", 11, [0.1])
    assert not ls.complete() and ls.missing() == ["c"]


def test_a_participant_whose_token_goes_is_not_waited_for() -> None:
    ls, _ = begun(0, "a", "b")
    ls.receive("b", 0, [0.2])
    ls.left("b")
    assert not ls.complete()
    ls.receive("a", 0, [0.1])
    assert ls.complete() and ls.commands() == {"a": [0.1]}
    ls.joined("b")  # a restarted autopilot comes back as a late joiner
    assert "b" not in ls.active


def test_startup_handshake_uses_its_own_deadline() -> None:
    ls, clock = barrier("a")
    ls.start()
    ls.begin(0, timeout_s=60.0)
    clock.now += 30.0
    assert ls.expire() == []
    clock.now += 31.0
    assert ls.expire() == ["a"]


# ---------------------------------------------------------------------------- restarts
def test_a_held_participant_is_waited_for_until_the_deadline_without_a_notice() -> None:
    ls, clock = begun(0, "a", "b")
    ls.receive("a", 0, [0.1])
    ls.held_leave("b")  # token gone: the launcher may be restarting it
    assert not ls.complete() and ls.missing() == ["b"] and ls.held == {"b"}
    clock.now += 0.49
    assert ls.expire() == []
    clock.now += 0.02
    assert ls.expire() == ["b"] and ls.complete() and ls.held == frozenset()


def test_a_restart_notice_holds_the_tick_for_the_grace_and_the_new_process_answers_it() -> None:
    ls, clock = begun(7, "a", "b")
    ls.receive("a", 7, [0.1])
    ls.held_leave("b")
    assert ls.restarting("b", grace_s=20.0)
    clock.now += 19.9  # far past the 0.5 s participant deadline
    assert ls.remaining_s() > 0.0 and ls.expire() == []
    assert not ls.receive("b", 7, [0.2])  # no token yet: not a participant's answer
    ls.joined("b")  # the new process
    assert ls.receive("b", 7, [0.2])
    assert ls.complete() and ls.commands() == {"a": [0.1], "b": [0.2]}
    assert ls.held == frozenset()
    ls.begin(8)
    assert ls.remaining_s() == 0.5  # back to the participant deadline


def test_a_hold_spans_ticks_when_the_dead_process_had_answered_and_expires_after_grace() -> None:
    ls, clock = begun(3, "a", "b")
    ls.receive("b", 3, [0.2])
    ls.restarting("b", grace_s=5.0)  # the notice came before the token's departure
    ls.held_leave("b")
    ls.receive("a", 3, [0.1])
    assert ls.complete() and ls.commands() == {"a": [0.1], "b": [0.2]}
    ls.begin(4)
    ls.receive("a", 4, [0.1])
    assert not ls.complete() and ls.missing() == ["b"]
    clock.now += 4.9
    assert ls.expire() == []
    clock.now += 0.2
    assert ls.expire() == ["b"]  # the grace passed: dropped like a silent participant
    assert ls.commands() == {"a": [0.1]} and "b" not in ls.active


def test_no_hold_for_a_process_that_is_not_restarted_or_a_dropped_participant() -> None:
    ls, clock = begun(0, "a", "b", "c")
    ls.held_leave("b")
    assert ls.gone("b")  # the launcher gave up on it: not waited for any more
    assert ls.missing() == ["a", "c"] and "b" not in ls.active
    clock.now += 1.0
    assert ls.expire() == ["a", "c"]
    assert not ls.restarting("c", grace_s=20.0)  # already dropped: it rejoins by answering


def periodic_barrier(period: int, *present: str) -> tuple[Lockstep, FakeClock]:
    """Vehicles a and b and a ``plume`` answering every ``period``-th tick; ``present`` joined."""
    clock = FakeClock()
    ls = Lockstep(["a", "b"], timeout_s=0.5, clock=clock, periodic={"plume": period})
    for p in present:
        ls.joined(p)
    return ls, clock


def test_a_periodic_participant_is_waited_for_only_on_the_ticks_its_period_divides() -> None:
    ls, _ = periodic_barrier(3, "a", "b", "plume")
    assert ls.missing_tokens() == []
    ls.start()
    for tick in range(7):
        ls.begin(tick)
        assert ls.waits("plume") == (tick in (0, 3, 6))
        ls.receive("a", tick, [0.1])
        ls.receive("b", tick, [0.2])
        assert ls.complete() == (tick not in (0, 3, 6)), tick
        if tick % 3 == 0:
            assert ls.missing() == ["plume"]
            assert ls.receive("plume", tick, ())
            assert ls.complete()
        assert ls.commands() == {"a": [0.1], "b": [0.2]}  # its answer is no motor command


def test_the_start_waits_for_vehicle_tokens_only_and_a_late_periodic_one_joins_by_answering() -> (
    None
):
    ls, clock = periodic_barrier(2)
    ls.joined("a")
    assert ls.missing_tokens() == ["b"]  # not the plume's
    ls.joined("b")
    ls.start()
    ls.begin(0)
    assert not ls.waits("plume")  # absent at the start: not waited for
    ls.joined("plume")
    answered(ls, 0, "a", "b")
    assert ls.complete()
    ls.begin(1)
    assert not ls.receive("plume", 1, ())  # not its tick: it answers even ticks only
    answered(ls, 1, "a", "b")
    assert ls.complete()  # an answer to a tick it does not answer did not make it wait
    ls.begin(2)
    assert not ls.waits("plume")
    assert ls.receive("plume", 2, ())  # its first answer admits it
    ls.begin(4)
    assert ls.waits("plume")
    clock.now += 0.6
    assert ls.expire() == ["a", "b", "plume"]


def test_a_periodic_participant_dropped_at_the_deadline_rejoins_without_stalling_other_ticks() -> (
    None
):
    ls, clock = periodic_barrier(2, "a", "b", "plume")
    ls.start()
    ls.begin(0)
    answered(ls, 0, "a", "b")
    clock.now += 0.6
    assert ls.expire() == ["plume"]
    ls.begin(1)
    assert ls.receive("plume", 0, ()) is False  # its late answer to tick 0: too late to count
    assert not ls.waits("plume")  # ...and it makes no odd tick wait for it
    answered(ls, 1, "a", "b")
    assert ls.complete()
    ls.begin(2)
    assert ls.waits("plume")  # active again since it answered a tick since its drop


def test_a_held_periodic_participant_holds_only_its_own_ticks() -> None:
    ls, clock = periodic_barrier(3, "a", "b", "plume")
    ls.start()
    ls.begin(1)
    assert ls.held_leave("plume") and ls.restarting("plume", 10.0)
    answered(ls, 1, "a", "b")
    assert ls.complete()  # tick 1 is not the plume's
    ls.begin(3)
    answered(ls, 3, "a", "b")
    clock.now += 5.0
    assert not ls.complete() and ls.expire() == []  # held within its grace
    ls.joined("plume")
    assert ls.receive("plume", 3, ())
    assert ls.complete() and ls.held == frozenset()


def test_with_a_rejoin_window_only_a_recent_answer_rejoins() -> None:
    """Realtime: answers that sat in a healed link's backlog do not rejoin; a recent one does."""
    clock = FakeClock()
    ls = Lockstep(["a", "b"], timeout_s=0.5, clock=clock, rejoin_window=12)
    ls.joined("a")
    ls.joined("b")
    ls.start()
    ls.begin(3)
    ls.receive("a", 3, [0.1])
    clock.now += 1.0
    assert ls.expire() == ["b"]
    ls.begin(600)
    assert not ls.receive("b", 3, [0.0])  # the tick it missed, 597 ticks late
    assert not ls.receive("b", 587, [0.0])  # 13 behind
    assert ls.active == {"a"}
    assert not ls.receive("b", 588, [0.0])  # 12 behind: back (not this tick's command) ...
    assert ls.active == {"a", "b"} and ls.missing() == ["a", "b"]  # ... and waited for
    assert ls.receive("b", 600, [0.5])
