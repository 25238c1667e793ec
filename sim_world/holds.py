"""Holding the clock for processes that come back: restarted participants, the recorder (also
while its health says it cannot write), and whoever leaves with the router (lockstep mode).

See docs/physics.md, "Restarts: the clock waits (lockstep)".
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Sequence

from sim_world.lockstep import Lockstep

log = logging.getLogger(__name__)

BACKFILL_TICKS = 256  # the recent ticks re-sent to a restarted recorder (sim/backfill)
RECORDER = "recorder"  # the recorder's node name: the clock waits for its restart too
ROUTER = "router"  # the router's node name: while it is away, every departure is held


class Holds:
    """Who the clock is held for and until when; not thread-safe (the physics node holds its
    lock). With ``grace_s = 0`` (realtime mode, or ``time.restart_grace_s = 0``) nothing is
    held: a participant whose token goes is dropped at once."""

    def __init__(
        self,
        grace_s: float,
        word_s: float,
        clock: Callable[[], float],
        republish_s: float,
    ) -> None:
        self.grace_s = grace_s  # how long a restarting process may take, beyond its backoff
        self._word_s = word_s  # how long to wait for the launcher's word on the recorder
        self._clock = clock
        self._republish_s = republish_s
        self._republished = -republish_s  # wall time of the last re-publication during a hold
        self._recorder_arrivals = 0
        self.recorder_lost = False  # the recorder's token went: hold before the next tick
        self._recorder_until = 0.0  # it is being restarted: hold until it is back, or this
        self._seen = 0  # the recorder's arrivals when the current wait began
        self._word_until = 0.0  # the current wait's deadline for the launcher's word
        # The router left: until this wall time every participant whose token goes is held for
        # the grace (its process is most likely alive, cut off with the router).
        self._router_until = 0.0
        self._outage_tick = -1  # the tick that was current when the router went
        # The last BACKFILL_TICKS ticks as published: (key, payload) of the tick and its states.
        self.recent: deque[list[tuple[str, bytes]]] = deque(maxlen=BACKFILL_TICKS)

    @property
    def enabled(self) -> bool:
        return self.grace_s > 0.0

    # ------------------------------------------------------------------ participants
    def leave(self, barrier: Lockstep, participant: str) -> None:
        """``participant``'s token went: hold it (the launcher may be restarting it; to the
        router's return if it left with the router), or drop it when nothing is held."""
        if not self.enabled:
            barrier.left(participant)
            return
        barrier.held_leave(participant)
        until = self._router_until - self._clock()
        if until > 0.0:
            barrier.restarting(participant, until)

    def restart_notice(
        self, barrier: Lockstep, participants: Sequence[str], restarting: bool, delay_s: float
    ) -> list[str]:
        """The launcher's word on the process of ``participants``: hold them for its backoff
        and the grace, or drop them; returns those held or dropped."""
        if restarting:
            return [p for p in participants if barrier.restarting(p, delay_s + self.grace_s)]
        return [p for p in participants if barrier.gone(p)]

    # ------------------------------------------------------------------ router
    def router(self, barrier: Lockstep, alive: bool, tick: int) -> bool:
        """The router's token came (``alive``) or went at ``tick``: whoever leaves with it is
        held for the grace, the recorder's hold too. Returns whether it was away."""
        was_away = self._router_until > 0.0
        if alive:
            self._router_until = 0.0
            return was_away
        self._router_until = self._clock() + self.grace_s
        self._outage_tick = tick
        for participant in barrier.held:
            barrier.restarting(participant, self.grace_s)
        self._recorder_until = max(self._recorder_until, self._router_until)
        return was_away

    # ------------------------------------------------------------------ re-publication
    def republish_due(self) -> bool:
        """Whether to re-send the held tick now (every ``republish_s`` during a hold)."""
        now = self._clock()
        if now - self._republished < self._republish_s:
            return False
        self._republished = now
        return True

    def resend_states(self, tick: int) -> bool:
        """Whether a re-sent ``tick`` goes with its states: subscribers cut off with the
        router missed them."""
        return self._outage_tick == tick

    def remember(self, entries: list[tuple[str, bytes]]) -> None:
        """A tick as published (its key and payload, its states'): kept for a backfill."""
        if self.enabled:
            self.recent.append(entries)

    # ------------------------------------------------------------------ recorder
    def recorder_presence(self, alive: bool) -> None:
        """The recorder's token came or went (when it went: hold before the next tick)."""
        self._recorder_arrivals += alive
        self.recorder_lost = not alive

    def recorder_notice(self, restarting: bool, delay_s: float) -> None:
        """The launcher's word on the recorder: wait for it up to its backoff and the grace,
        or not at all."""
        self._recorder_until = self._clock() + delay_s + self.grace_s if restarting else 0.0
        self.recorder_lost = self.recorder_lost and restarting

    def recorder_error(self, failing: bool) -> None:
        """The recorder's health says it cannot write (a full disk: hold before the next tick,
        as for a restart, up to the grace) or that it records again (as if it were back)."""
        if failing:
            self.recorder_lost = True
            self._recorder_until = self._clock() + self.grace_s
        else:
            self.recorder_presence(True)

    def begin_recorder_wait(self) -> None:
        """The next tick waits for a recorder's token: up to ``word_s`` for the launcher's
        word, up to the backoff and grace of a restart it announces."""
        self._seen = self._recorder_arrivals
        self._word_until = self._clock() + self._word_s

    def recorder_wait_s(self) -> float | None:
        """How much longer the wait may last; None once a recorder is back."""
        if self._recorder_arrivals != self._seen:
            return None
        return max(self._word_until, self._recorder_until) - self._clock()

    def end_recorder_wait(self) -> bool:
        """The wait is over: whether a recorder came back."""
        self.recorder_lost = False
        self._recorder_until = 0.0
        return self._recorder_arrivals != self._seen


class UnreachableGrace:
    """A tick whose deadline passed without the answers of participants whose token is up
    waits up to ``grace_s`` in all before it drops them (lockstep, ``time.unreachable_grace_s``;
    0: off): a process slowed down by a loaded machine changes no bit, and a partitioned host
    whose link lease outlives the cut has no token to leave. See docs/physics.md, "Lockstep"."""

    def __init__(self, grace_s: float, clock: Callable[[], float]) -> None:
        self.grace_s = grace_s
        self._clock = clock
        self._tick = -1  # the tick held for the grace
        self._since = 0.0

    def hold(self, barrier: Lockstep, tick: int) -> bool:
        """Tick ``tick``'s deadline passed: extend it to the grace, once; whether it now waits."""
        if self.grace_s <= 0.0 or self._tick == tick:
            return False
        now = self._clock()
        self._tick, self._since = tick, now
        timeout = barrier.timeout_s
        barrier.extend(now + max(0.0, self.grace_s - timeout))
        log.warning(
            "tick %d: no answer from %s for %.2f s: holding the clock up to %.1f s in all "
            "(unreachable grace)",
            tick,
            ", ".join(barrier.missing()),
            timeout,
            self.grace_s,
        )
        return True

    def holding(self, tick: int) -> bool:
        return self._tick == tick

    def waited_s(self, tick: int, timeout_s: float) -> float:
        """How long tick ``tick`` waited before it dropped someone."""
        return max(timeout_s, self.grace_s) if self._tick == tick else timeout_s

    def dropped(self) -> None:
        self._tick = -1  # the drop is the report

    def report_back(self, barrier: Lockstep, tick: int) -> None:
        """Log who answered again: a dropped participant back, a silent hold that ended."""
        for participant, at in barrier.rejoined:
            log.warning("%s answered tick %d: back in the lockstep", participant, at)
        barrier.rejoined.clear()
        if self._tick == tick:
            log.warning(
                "tick %d: every participant answered after %.2f s: the run goes on",
                tick,
                self._clock() - self._since,
            )
            self._tick = -1
