"""The stepped clock as pure logic: who holds it, how far the world may run, whom to answer.

In ``time.mode = "stepped"`` the physics runs the lockstep as usual but, once a tick is
published and answered by every participant, goes on to the next one only while the clock's
holder has granted it (``clock/step``: ``StepRequest`` → ``StepReply``). The world is *paused at
tick k* when tick k is published, every active autopilot has answered it, and its commands are
not applied yet; a grant of n ticks runs it to tick k + n and pauses it there again.

One client holds the clock: the first one to ask, until its liveliness token goes away. A
request from another client, or a second request while one is running, is refused with a reason.
The physics node feeds this from Zenoh callbacks under its own lock; ``Q`` is whatever the caller
answers the request through (a ``swarmbus.reqrep.Incoming`` there, anything in tests).
"""

from __future__ import annotations

from typing import Generic, TypeVar

from swarmbus.errors import PlumeswarmError

Q = TypeVar("Q")


class StepRefused(PlumeswarmError):
    """A grant the clock cannot take: ``field`` of the request and the reason, one line."""

    def __init__(self, field: str, reason: str) -> None:
        self.field = field
        self.reason = reason
        super().__init__(f"{field}: {reason}")


class SteppedClock(Generic[Q]):
    """Holder, granted tick and the request to answer once it is reached; not thread-safe."""

    def __init__(self) -> None:
        self.holder: str | None = None
        self.target = 0  # the world may publish ticks up to and including this one
        self._pending: Q | None = None

    def request(self, client: str, ticks: int, paused_tick: int, answer_to: Q) -> int:
        """Grant ``ticks`` more ticks to ``client`` from ``paused_tick``; returns the tick the
        world will pause at next. Raises :class:`StepRefused` when another client holds the
        clock or a grant is still running."""
        if self.holder is not None and self.holder != client:
            raise StepRefused(
                "client",
                f"the clock is held by {self.holder}; one client steps a world at a time "
                "(it is free again when that client disconnects)",
            )
        if self._pending is not None:
            raise StepRefused(
                "ticks", f"a step to tick {self.target} is still running; wait for its reply"
            )
        if ticks < 1:
            raise StepRefused("ticks", f"must be >= 1, got {ticks}")
        self.holder = client
        self.target = max(self.target, paused_tick) + ticks
        self._pending = answer_to
        return self.target

    def released(self, client: str) -> bool:
        """``client``'s token went away: the clock is free (a running grant still runs)."""
        if self.holder != client:
            return False
        self.holder = None
        return True

    def may_advance(self, tick: int) -> bool:
        """Whether the world, paused at ``tick``, may apply its commands and step."""
        return tick < self.target

    def reached(self, tick: int) -> Q | None:
        """The request to answer now that ``tick`` is published and answered, if any."""
        if self._pending is None or tick < self.target:
            return None
        pending, self._pending = self._pending, None
        return pending

    def abandon(self) -> Q | None:
        """The request still waiting when the world stops (to answer with an error)."""
        pending, self._pending = self._pending, None
        return pending
