"""A controllable monotonic clock for pure-logic tests (lockstep, holds, pacing)."""

from __future__ import annotations


class FakeClock:
    """Returns ``now``; a test moves it by hand (``clock.now += 0.5``)."""

    def __init__(self, now: float = 100.0) -> None:
        self.now = now

    def __call__(self) -> float:
        return self.now
