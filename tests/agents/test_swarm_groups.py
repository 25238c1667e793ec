"""The stepped Swarm client with several vehicles per autopilot process: ``plumeswarm up
--stepped --vehicles-per-process 2`` (router, physics, the autopilots of the test scenario's
three vehicles: one process of uav1 and uav2, one of uav3). Such a process declares a token per
vehicle and one under its own name, ``autopilot-uav1-plus1``; the client's vehicles are the
scenario's, and a step waits for no status of a vehicle that does not exist."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from agents import Swarm
from swarmbus.scenario import load_scenario
from swarmbus.session import Presence
from tests.support.mavclient import write_scenario
from tests.support.procs import wait_until
from tests.support.upstack import plumeswarm_up


def test_a_process_of_two_vehicles_is_no_vehicle_of_the_stepped_client(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 3)
    vehicles = sorted(v.id for v in load_scenario(path).vehicles)
    args = ("--headless", "--stepped", "--roles", "router,physics,autopilot")
    with (
        plumeswarm_up(path, tmp_path, *args, "--vehicles-per-process", "2") as up,
        Swarm.connect(connect=[up.endpoint], command_timeout_s=5.0) as sw,
    ):
        presence = Presence(sw.session, sw.keys)
        try:
            names = {"autopilot-uav1-plus1", "autopilot-uav1", "autopilot-uav3"}
            assert presence.wait_for(lambda alive: names <= alive, 60.0), presence.alive
        finally:
            presence.close()
        wait_until(lambda: sw.vehicles == vehicles, 120.0, "the states of tick 0")
        caplog.set_level(logging.WARNING, logger="agents.swarm")
        for _ in range(3):
            reply = sw.step(12)
        assert sw.autopilots_alive() == vehicles
        assert {v: sw.state(v).tick for v in vehicles} == dict.fromkeys(vehicles, reply.tick)  # type: ignore[union-attr]
        late = [r.getMessage() for r in caplog.records if "no state or status" in r.getMessage()]
        assert late == []
