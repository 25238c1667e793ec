"""The log lines for participants dropped at a tick's deadline (docs/physics.md, Lockstep 4;
Restarts): vehicles lose their motors, the plume its sensor tick, a held one its grace."""

from __future__ import annotations

import logging

import pytest

from sim_world.drops import report_dropped


def lines(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]


def test_each_kind_of_drop_has_its_line(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="sim_world.drops")
    report_dropped(12, ["uav1", "uav3", "plume"], {"uav3", "plume"}, 0.5, 30.0)
    assert lines(caplog) == [
        "tick 12: dropped uav1, uav3 after 0.50 s without actuators (motors off)",
        "tick 12: no plume sample after 0.50 s: this sensor tick's readings are unavailable; "
        "the plume service takes part again once it answers a sensor tick",
        "tick 12: restart grace of 30.0 s passed: uav3 dropped (motors off, failsafe)",
    ]


def test_nobody_dropped_says_nothing(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.WARNING, logger="sim_world.drops")
    report_dropped(3, [], {"uav1"}, 0.5, 30.0)
    assert lines(caplog) == []


def test_in_realtime_the_dropped_vehicles_go_to_the_physics_failsafe(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger="sim_world.drops")
    report_dropped(7, ["uav2"], set(), 2.0, 0.0, "the physics' failsafe")
    assert lines(caplog) == [
        "tick 7: dropped uav2 after 2.00 s without actuators (the physics' failsafe)"
    ]
