"""``vehicle/<id>/state``: the physics puts a vehicle's state only while someone subscribes to
it (Zenoh's matching status); everyone else reads ``sim/tick``. A subscriber that appears
mid-run gets every state from its first one on, and none are sent once it is gone."""

from __future__ import annotations

import re
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from swarmbus.codec import decode
from swarmbus.messages import NodeHealth, VehicleState
from tests.support.physics_rig import KEYS, Watch, fly_a_and_b, two_vehicle_scenario
from tests.support.procs import Network, NodeProcs, wait_until


class Health:
    """The physics' count of per-vehicle state puts, from its health detail (once a second)."""

    def __init__(self, session: zenoh.Session) -> None:
        self.lock = threading.Lock()
        self.reports: list[tuple[int, int]] = []  # (tick, states sent)
        self._sub = session.declare_subscriber(KEYS.node_health("physics"), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        health = decode(sample.payload.to_bytes(), NodeHealth)
        found = re.search(r"\btick (\d+) dropped \d+ states (\d+)", health.detail)
        if found:
            with self.lock:
                self.reports.append((int(found.group(1)), int(found.group(2))))

    def after(self, tick: int) -> tuple[int, int] | None:
        """The first report from at least ``tick``."""
        with self.lock:
            return next((r for r in self.reports if r[0] >= tick), None)

    def close(self) -> None:
        self._sub.undeclare()


class States:
    """Every ``vehicle/*/state`` seen by a subscriber declared when the test says."""

    def __init__(self, session: zenoh.Session) -> None:
        self.lock = threading.Lock()
        self.ticks: dict[str, list[int]] = {}
        self._sub = session.declare_subscriber(KEYS.all_vehicle_states(), self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        state = decode(sample.payload.to_bytes(), VehicleState)
        assert KEYS.vehicle_id_of(str(sample.key_expr)) == state.vehicle_id
        with self.lock:
            self.ticks.setdefault(state.vehicle_id, []).append(state.tick)

    def count(self, vid: str) -> int:
        with self.lock:
            return len(self.ticks.get(vid, []))

    def close(self) -> None:
        self._sub.undeclare()


@pytest.fixture
def running(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> Iterator[tuple[zenoh.Session, Watch, Health]]:
    net, session = network
    watch, health = Watch(session), Health(session)
    procs = NodeProcs(net, log_dir=tmp_path)
    sc = two_vehicle_scenario(tmp_path, timeout_s=2.0)
    fly_a_and_b(procs, sc)
    try:
        yield session, watch, health
    finally:
        procs.stop_all()
        health.close()
        watch.close()


def test_no_state_puts_without_a_subscriber_and_a_late_subscriber_gets_every_state(
    running: tuple[zenoh.Session, Watch, Health],
) -> None:
    session, watch, health = running
    wait_until(lambda: watch.last_tick >= 60, 60.0, "tick 60")
    quiet = wait_until(lambda: health.after(60), 30.0, "a physics health report after tick 60")
    assert quiet is not None
    assert quiet[1] == 0, f"the physics put {quiet[1]} states that nobody subscribed to"

    joined_at = watch.last_tick
    states = States(session)  # joins mid-run, as the demo's digest or a Swarm client does
    try:
        wait_until(lambda: min(states.count("a"), states.count("b")) >= 100, 60.0, "100 states")
        with states.lock:
            seen = {vid: list(ticks) for vid, ticks in states.ticks.items()}
        for vid, ticks in seen.items():
            first = ticks[0]
            assert first >= joined_at, vid
            assert ticks == list(range(first, first + len(ticks))), f"{vid}: a gap or a repeat"
        # The target tick is fixed before waiting: a report's tick is always behind the ticks
        # arriving meanwhile, so a moving target would be met only by a lucky poll.
        heard_at = watch.last_tick
        sending = wait_until(lambda: health.after(heard_at), 30.0, "a report while heard")
        assert sending is not None and sending[1] > 0
    finally:
        states.close()

    # Gone again: once the physics has seen the subscriber leave, its count stops growing.
    def settled() -> bool:
        with health.lock:
            reports = health.reports[-3:]
        return (
            len(reports) == 3 and reports[0][1] == reports[-1][1] and reports[-1][0] > reports[0][0]
        )

    wait_until(settled, 60.0, "no more state puts after the subscriber left")
