"""The Swarm client's public surface changes only on purpose (DESIGN.md "Public surfaces")."""

from __future__ import annotations

import inspect

import agents
from agents import Swarm, VehicleCommander


def test_exports() -> None:
    assert set(agents.__all__) == {
        "CommandRejected",
        "CommandTimeout",
        "PlumeError",
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
    assert list(inspect.signature(VehicleCommander.takeoff).parameters)[1:] == ["alt_m"]
