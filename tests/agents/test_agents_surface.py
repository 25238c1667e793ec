"""The Swarm client's public surface changes only on purpose."""

from __future__ import annotations

import inspect

import pytest

import agents
from agents import Swarm, VehicleCommander
from agents.swarm_clients import takeoff_altitude


def test_exports() -> None:
    assert set(agents.__all__) == {
        "ClockError",
        "CommandRejected",
        "CommandTimeout",
        "PlumeError",
        "RadioReadError",
        "RadioSent",
        "RadioUnavailable",
        "Swarm",
        "SwarmError",
        "VehicleCommander",
        "WaitTimeout",
    }


def test_swarm_surface() -> None:
    params = inspect.signature(Swarm.connect).parameters
    assert list(params)[:2] == ["world", "connect"]
    assert params["world"].default == "default" and params["connect"].default is None
    for name in ("vehicles", "state", "status", "reading", "subscribe", "command", "wait_until"):
        assert hasattr(Swarm, name), name
    for name in ("step", "step_until", "sim_time", "holds_clock"):
        assert hasattr(Swarm, name), name
    for name in ("radio", "radio_tick", "wait_radio", "fetch_radio", "radio_links"):
        assert hasattr(Swarm, name), name
    assert list(inspect.signature(Swarm.step).parameters)[1:2] == ["ticks"]
    assert list(inspect.signature(Swarm.step_until).parameters)[1:3] == [
        "predicate",
        "timeout_sim_s",
    ]
    assert "sim_timeout_s" in inspect.signature(Swarm.wait_until).parameters
    assert hasattr(Swarm, "__enter__") and hasattr(Swarm, "__exit__")


def test_vehicle_commands() -> None:
    wanted = {
        "arm",
        "disarm",
        "takeoff",
        "land",
        "rtl",
        "hold",
        "goto",
        "upload_mission",
        "start_mission",
        "setpoint",
    }
    assert wanted <= {n for n in dir(VehicleCommander) if not n.startswith("_")}
    assert list(inspect.signature(VehicleCommander.goto).parameters)[1:4] == ["x", "y", "z"]
    takeoff = inspect.signature(VehicleCommander.takeoff).parameters
    assert list(takeoff)[1:] == ["altitude_m", "alt_m"]
    assert takeoff["alt_m"].kind is inspect.Parameter.KEYWORD_ONLY  # the old name, deprecated


def test_takeoff_takes_its_old_keyword_with_a_deprecation_warning() -> None:
    assert takeoff_altitude(7.5, None) == 7.5
    with pytest.warns(DeprecationWarning, match=r"alt_m=.*altitude_m="):
        assert takeoff_altitude(None, 7.5) == 7.5
    with pytest.raises(TypeError, match="altitude_m only"):
        takeoff_altitude(7.5, 7.5)
    with pytest.raises(TypeError, match="needs altitude_m"):
        takeoff_altitude(None, None)
