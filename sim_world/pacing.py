"""Wall-clock pacing of the physics: the realtime mode's hold, and when ``sim/clock`` and the
health go out with which achieved real-time factor. The wall clock only measures and paces;
it never drives the physics.

See docs/physics.md, "Speed modes and clock".
"""

from __future__ import annotations

from collections.abc import Callable

HEALTH_PERIOD_S = 1.0


class Pacer:
    """Wall and sim time at the start of the pacing and of the last clock; not thread-safe
    (the physics loop alone uses it)."""

    def __init__(
        self,
        clock: Callable[[], float],
        speed_factor: float,
        clock_period_s: float,
        health_period_s: float = HEALTH_PERIOD_S,
    ) -> None:
        self._clock = clock
        self._speed_factor = speed_factor
        self._clock_period_s = clock_period_s
        self._health_period_s = health_period_s
        self._wall_start = clock()
        self._sim_start = 0.0
        self._clock_wall = self._wall_start  # wall and sim time of the last clock
        self._clock_sim = 0.0
        self._health_wall = self._wall_start
        self.real_time_factor = 0.0  # sim seconds per wall second over the last clock period

    def reset(self, sim_time_s: float) -> float:
        """Pace from ``sim_time_s`` now (after the start handshake); returns the wall time."""
        self._wall_start = self._clock()
        self._sim_start = sim_time_s
        self._clock_wall = self._wall_start
        self._clock_sim = sim_time_s
        return self._wall_start

    def delay_s(self, sim_time_s: float) -> float:
        """Realtime mode: how long to hold the tick of ``sim_time_s`` until the wall clock
        reaches its sim time divided by the speed factor (<= 0: no hold)."""
        elapsed_sim_s = sim_time_s - self._sim_start
        return self._wall_start + elapsed_sim_s / self._speed_factor - self._clock()

    def clock_due(self) -> float | None:
        """The wall time now if a clock period has passed since the last clock, else None."""
        now = self._clock()
        return now if now - self._clock_wall >= self._clock_period_s else None

    def measure(self, sim_time_s: float, now: float) -> float:
        """A clock goes out at wall time ``now`` for ``sim_time_s``: the real-time factor since
        the last one (the previous one while sim time did not advance)."""
        wall = now - self._clock_wall
        if wall > 0.0 and sim_time_s > self._clock_sim:
            self.real_time_factor = (sim_time_s - self._clock_sim) / wall
        self._clock_wall = now
        self._clock_sim = sim_time_s
        return self.real_time_factor

    def health_due(self, now: float, force: bool = False) -> bool:
        """Whether the health goes out with this clock (about once a health period)."""
        if force or now - self._health_wall >= self._health_period_s:
            self._health_wall = now
            return True
        return False

    def elapsed_s(self) -> float:
        """Wall seconds since the pacing started."""
        return self._clock() - self._wall_start
