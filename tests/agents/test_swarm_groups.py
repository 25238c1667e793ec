"""The Swarm client on autopilot processes that serve several vehicles (``plumeswarm up
--vehicles-per-process 2``: one process for uav1 and uav2, one for uav3). Such a process has a
presence token of its own (``autopilot-uav1-plus1``) beside one per vehicle it serves: the
client counts the vehicles, not the process, and a step returns once every vehicle's state and
status of the tick are in, without waiting out its timeout for a vehicle that does not exist.
"""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from agents import Swarm
from swarmbus.session import Presence
from tests.support.procs import wait_until
from tests.support.upstack import plumeswarm_up

ROLES = "router,plume,physics,autopilot"
VEHICLES = ["uav1", "uav2", "uav3"]
GROUP = "autopilot-uav1-plus1"  # the process serving uav1 and uav2


def test_processes_of_two_vehicles_the_client_sees_the_vehicles_and_steps_on_them(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger="agents.swarm")
    args = ("--headless", "--stepped", "--roles", ROLES, "--vehicles-per-process", "2")
    with (
        plumeswarm_up(None, tmp_path, *args) as up,
        Swarm.connect(connect=[up.endpoint], command_timeout_s=10.0) as sw,
    ):
        assert {GROUP, "autopilot-uav3"} <= set(up.pids()), up.pids()
        presence = Presence(sw.session, sw.keys)
        try:
            tokens = {GROUP, *(f"autopilot-{v}" for v in VEHICLES)}
            wait_until(lambda: tokens <= set(presence.alive), 60.0, "every autopilot token")
        finally:
            presence.close()
        assert sw.autopilots_alive() == VEHICLES
        for _ in range(3):
            reply = sw.step(12)
            for vid in VEHICLES:
                state, status = sw.state(vid), sw.status(vid)
                assert state is not None and state.tick == reply.tick, (vid, state)
                assert status is not None and status.sim_time_s >= reply.sim_time_s, vid
    late = [r.getMessage() for r in caplog.records if "no state or status" in r.getMessage()]
    assert not late, late
