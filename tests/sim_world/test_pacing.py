"""Pacing (docs/physics.md, "Speed modes and clock") with a fake clock: the realtime hold is
sim time over the speed factor; the real-time factor is sim over wall time between clocks.
The times are binary fractions, so every expected value is exact."""

from __future__ import annotations

from sim_world.pacing import Pacer
from tests.support.fake_clock import FakeClock

CLOCK_PERIOD_S = 0.125


def pacer(speed_factor: float = 1.0) -> tuple[Pacer, FakeClock]:
    clock = FakeClock()
    return Pacer(clock, speed_factor, CLOCK_PERIOD_S, health_period_s=1.0), clock


def test_realtime_holds_a_tick_until_its_sim_time_over_the_speed_factor() -> None:
    p, clock = pacer(speed_factor=2.0)
    p.reset(sim_time_s=8.0)  # e.g. resumed from a checkpoint: paced from there
    assert p.delay_s(9.0) == 0.5  # one sim second at twice real time
    clock.now += 0.25
    assert p.delay_s(9.0) == 0.25
    clock.now += 0.75
    assert p.delay_s(9.0) == -0.5  # late: no hold
    assert p.elapsed_s() == 1.0


def test_the_real_time_factor_is_sim_over_wall_time_since_the_last_clock() -> None:
    p, clock = pacer()
    p.reset(sim_time_s=0.0)
    assert p.measure(1.0, clock.now + 0.5) == 2.0
    assert p.measure(1.25, clock.now + 1.0) == 0.5  # 0.25 sim s in 0.5 wall s
    assert p.measure(1.25, clock.now + 2.0) == 0.5  # paused: the last factor stands
    assert p.real_time_factor == 0.5


def test_a_clock_is_due_once_a_clock_period_has_passed_since_the_last() -> None:
    p, clock = pacer()
    p.reset(sim_time_s=0.0)
    clock.now += 0.0625
    assert p.clock_due() is None
    clock.now += 0.0625
    now = p.clock_due()
    assert now == 100.125
    p.measure(0.5, now)
    assert p.clock_due() is None


def test_the_health_goes_out_about_once_a_period_or_when_forced() -> None:
    p, _ = pacer()
    assert not p.health_due(100.5)
    assert p.health_due(101.0)
    assert not p.health_due(101.5)
    assert p.health_due(101.5, force=True)
    assert not p.health_due(102.25)
    assert p.health_due(102.5)
