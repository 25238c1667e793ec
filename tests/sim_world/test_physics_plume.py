"""The physics process and the plume: each sensor tick sampled by the plume service and carried
by the next tick; the clock waits for the sample as for a participant and drops a silent plume."""

from __future__ import annotations

import itertools
import threading
from pathlib import Path

import zenoh

from swarmbus.codec import decode, encode
from swarmbus.messages import FieldSample, PlumeQuery, PlumeSample, PlumeValues, SimTick
from swarmbus.reqrep import request
from tests.support.physics_rig import (
    KEYS,
    Watch,
    exit_code,
    two_vehicle_scenario,
    wait_for_plume,
)
from tests.support.procs import NodeProcs, wait_until


def ticks_with_a_plume(
    procs: NodeProcs, watch: Watch, scenario: Path, max_ticks: int
) -> list[SimTick]:
    """Once a plume's token is up: a physics with no autopilot run to ``max_ticks``; its ticks."""
    wait_for_plume(watch)
    physics = procs.start(
        "physics", "--scenario", str(scenario), "--set", f"max_ticks={max_ticks}",
        "--set", "wait_for_autopilots=false", name="physics",
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    count = max_ticks + 1
    wait_until(lambda: len(watch.raw) == count, 10.0, f"ticks 0..{max_ticks} at the subscriber")
    return [decode(watch.raw[k], SimTick) for k in range(count)]


def test_the_plume_service_samples_each_sensor_tick_and_the_next_tick_carries_it(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path)
    procs.start("plume", "--scenario", str(sc), name="plume")
    ticks = ticks_with_a_plume(procs, watch, sc, 20)
    assert all(t.plume_queried for t in ticks)  # sensor every tick in this scenario
    assert ticks[0].plume_values is None
    for prev, t in itertools.pairwise(ticks):
        assert t.plume_values is not None and t.plume_values.tick == prev.tick
        points = [s.position_enu_m for s in prev.states]
        expected = request(
            watch.session,
            KEYS.plume_concentration(),
            encode(PlumeQuery(points_enu_m=points, sim_time_s=prev.sim_time_s)),
            PlumeValues,
            10.0,
        ).values_g_m3
        assert t.plume_values.values_g_m3 == expected


class StandInPlume:
    """Plays the plume service on the test's session: its token, and on every tick of
    ``sim/sensor`` (every tick is a sensor tick in this scenario) a ``FieldSample`` of made-up
    values —
    after ``DELAY_S`` before the ticks in ``silent``, none for those, at once after them;
    counts queries on plume/concentration (the physics must send none) and notes the newest
    tick seen when each answer went out."""

    DELAY_S = 0.05

    def __init__(self, watch: Watch, silent: range) -> None:
        session = watch.session
        self.watch = watch
        self.silent = silent
        self.queries = 0
        self.seen_when_answered: dict[int, int] = {}
        self._pub = session.declare_publisher(KEYS.plume_sample())
        self._token = session.liveliness().declare_token(KEYS.node_health("plume"))
        self._sub = session.declare_subscriber(KEYS.sensor_tick(), self._on_tick)
        self._q = session.declare_queryable(KEYS.plume_concentration(), self._on_query)

    @staticmethod
    def values(tick: int) -> list[float]:
        return [tick + 0.25, tick + 0.5]

    def _on_tick(self, sample: zenoh.Sample) -> None:
        msg = decode(sample.payload.to_bytes(), SimTick)
        if msg.tick in self.silent:
            return
        if msg.tick < self.silent.start:
            threading.Event().wait(self.DELAY_S)
        with self.watch.lock:
            self.seen_when_answered[msg.tick] = self.watch.last_tick
        answer = FieldSample(
            tick=msg.tick, sim_time_s=msg.sim_time_s, values_g_m3=self.values(msg.tick)
        )
        self._pub.put(encode(answer))

    def _on_query(self, query: zenoh.Query) -> None:
        self.queries += 1

    def close(self) -> None:
        for entity in (self._sub, self._q, self._token, self._pub):
            entity.undeclare()


def test_the_clock_waits_for_the_plume_sample_asks_nothing_and_drops_a_silent_plume(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """The physics waits for the plume as for a participant: tick k + 1 carries exactly what
    the plume answered to tick k, and only after it answered; it never queries the plume. A
    plume silent past the participant timeout is dropped (that tick's values unavailable, no
    tick waits for it: with no autopilot the physics runs on at once) and, once it answers a
    tick again, every tick waits for it as before."""
    procs, watch = rig
    # participant timeout 1 s; without the grace that waits for a late plume whose token is up
    sc = two_vehicle_scenario(tmp_path, extra_time="unreachable_grace_s = 0.0")
    plume = StandInPlume(watch, silent=range(5, 10))
    try:
        ticks = ticks_with_a_plume(procs, watch, sc, 400)
    finally:
        plume.close()
    assert plume.queries == 0
    waited = [t.tick for t in ticks if t.plume_queried]
    # 0..5 waited for (5 timed out), then none until it answered again; every one from then on
    back = waited[6]
    assert waited == [*range(0, 6), *range(back, 401)] and 10 < back < 400, waited
    for k in waited[:-1]:
        if k == 5:
            assert ticks[6].plume_values == PlumeSample(tick=5, values_g_m3=None)
            continue
        assert ticks[k + 1].plume_values == PlumeSample(tick=k, values_g_m3=plume.values(k))
        assert plume.seen_when_answered[k] <= k  # tick k + 1 was not out before the answer
    assert all(ticks[k].plume_values is None for k in range(7, back + 1))
    log = (tmp_path / "physics.log").read_text()
    assert "tick 5: no plume sample after 1.00 s" in log
