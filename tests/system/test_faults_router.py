"""The router is no single point of failure (lockstep): SIGKILL of the router while the three
vehicles fly their missions, under the launcher that ``plumeswarm up`` runs. The supervisor
restarts it on the same endpoint; every session reconnects by Zenoh's own reconnection
(``swarmbus.session.CONNECT_RETRY``) and declares its subscribers, queryables and token again.

Two layouts: the default one (every node a peer that listens: the peers also link to each other
directly, so the bus keeps working without the router) and one where every node is a *client*
of the router, so that the router's death cuts every link at once: every token disappears for
the physics, which holds the clock for all of them (docs/physics.md, "Restarts") until they are
back. There the router is killed twice in a row (the second time as soon as it is restarted),
so the outage outlasts ``participant_timeout_s``: without the hold every participant would be
dropped. In both, every vehicle's state stream and every reading is bit-identical to the run
without the kill (the same comparison as ``test_faults_resume``), and the missions finish.

Each test runs with the three vehicles (one per autopilot process) and, under the marker
``scale`` (``make test-scale``), with 32 in 4 autopilot processes of 8.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from tests.support.scale import SHAPES, Shape, patience
from tests.system.test_faults_resume import (
    ResumeRun,
    assert_nothing_lost,
    flight,
    fly_baseline,
    fly_with_kill,
    kill,
    on_first_leg,
)


@pytest.fixture(scope="module", params=SHAPES)
def shape(request: pytest.FixtureRequest) -> Shape:
    """The vehicles and how many each autopilot process serves."""
    shape: Shape = request.param
    return shape


@pytest.fixture(scope="module")
def baseline(shape: Shape, tmp_path_factory: pytest.TempPathFactory) -> ResumeRun:
    """The flight without any kill (every node a peer)."""
    vehicles, per_process = shape
    return fly_baseline(tmp_path_factory.mktemp("baseline"), per_process, vehicles)


def test_router_killed_mid_mission_peers_the_run_goes_on_and_nothing_is_lost(
    shape: Shape, baseline: ResumeRun, tmp_path: Path
) -> None:
    vehicles, per_process = shape
    f, killed_at = fly_with_kill(tmp_path, "router", per_process=per_process, vehicles=vehicles)
    assert_nothing_lost(f, baseline, killed_at)
    assert f.launcher.supervisor.procs["router"].restarts == 1


def test_router_killed_twice_mid_mission_clients_the_clock_holds_and_nothing_is_lost(
    shape: Shape, baseline: ResumeRun, tmp_path: Path
) -> None:
    vehicles, per_process = shape
    slow = patience(vehicles)
    with flight(tmp_path, per_process, "client", vehicles) as f:
        killed_at = on_first_leg(f)
        for _ in range(2):
            old = f.launcher.supervisor.pids()["router"]
            kill(f, "router")
            f.wait(
                lambda old=old: f.launcher.supervisor.pids()["router"] != old,  # type: ignore[misc]
                60.0 * slow,
                "router restarted",
            )
        f.wait(f.done, 300.0 * slow, "every mission finished and landed after the kills")
        time.sleep(0.5)
    assert_nothing_lost(f, baseline, killed_at)
    assert f.launcher.supervisor.procs["router"].restarts == 2
    log = (f.launcher.run_dir / "physics.log").read_text()
    assert "the router left: holding the clock" in log
    assert "the router is back" in log
    assert " dropped " not in log.replace(" dropped 0", ""), "a participant was dropped"
