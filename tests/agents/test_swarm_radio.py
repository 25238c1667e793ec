"""The Swarm client reads the radio: the messages talking behaviours publish
(``vehicle/<id>/radio``) and the link counts of the statuses, on a real stack.

``plumeswarm up --stepped`` flies the default scenario's three vehicles as cooperative
surge-casters (each publishes a ``Detection`` — where and when it detected gas — in a step in
which it did) over a radio that loses 30 % of every message. What the client reads is checked
against what it derives on its own: a detection's position is the vehicle's state at the
detection's time, as the physics published it; the link counts are the statuses' as they
crossed the bus, and their drop rate is the scenario's loss.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import math
import struct
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field

import msgspec
import pytest
import zenoh

from agents import ClockError, Swarm
from agents.behaviors.coop_surge_cast import Detection
from agents.swarm import RadioReadError, RadioSent, RadioUnavailable, WaitTimeout
from agents.swarm_radio import RadioKept, kind_of
from swarmbus.codec import decode
from swarmbus.messages import RadioBatch, RadioMessage, VehicleState, VehicleStatus
from swarmbus.scenario import DEFAULT_SCENARIO, Scenario, load_scenario
from tests.support.procs import REPO, wait_until
from tests.support.upstack import Up, plumeswarm_up

COOP = 'behavior = "agents.behaviors.coop_surge_cast:CooperativeSurgeCast"\n'
LOSS = 0.3
FLYERS = ("uav1", "uav2", "uav3")
ROLES = "router,plume,physics,autopilot"


@dataclass
class Seen:
    """What the test's own subscribers saw (Zenoh's thread), under ``lock``."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    states: dict[tuple[str, int], VehicleState] = field(default_factory=dict)
    radio: list[RadioSent] = field(default_factory=list)
    statuses: list[VehicleStatus] = field(default_factory=list)

    def on_state(self, state: VehicleState) -> None:
        with self.lock:
            self.states[(state.vehicle_id, state.tick)] = state

    def on_radio(self, sent: RadioSent) -> None:
        with self.lock:
            self.radio.append(sent)

    def on_status_sample(self, sample: zenoh.Sample) -> None:
        status = decode(sample.payload.to_bytes(), VehicleStatus)  # not through the client
        with self.lock:
            self.statuses.append(status)


@pytest.fixture(scope="module")
def coop_stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Up, Scenario]]:
    tmp = tmp_path_factory.mktemp("coop-radio")
    text = DEFAULT_SCENARIO.read_text().replace('type = "iris"\n', f'type = "iris"\n{COOP}')
    path = tmp / "scenario.toml"
    path.write_text(text + f"\n[radio]\nloss = {LOSS}\n")
    scenario = load_scenario(path)
    assert scenario.radio.loss == LOSS and scenario.radio.range_m == 0.0
    with plumeswarm_up(path, tmp, "--headless", "--stepped", "--roles", ROLES) as up:
        yield up, scenario


def _clock(sw: Swarm) -> float | None:
    try:
        return sw.sim_time + 1.0  # truthy at t = 0 too
    except ClockError:
        return None


def test_the_client_reads_the_detections_and_the_link_counts(
    coop_stack: tuple[Up, Scenario],
) -> None:
    up, scenario = coop_stack
    seen = Seen()
    with Swarm.connect(
        connect=[up.endpoint], command_timeout_s=20.0, radio_kept_ticks=100_000
    ) as sw:
        sub = sw.subscribe(on_state=seen.on_state, on_radio=seen.on_radio)
        raw = sw.session.declare_subscriber(sw.keys.all_vehicle_status(), seen.on_status_sample)
        wait_until(lambda: _clock(sw), 120.0, "the stepped world's clock")
        sw.step(1)
        for vid in FLYERS:
            sw.command(vid).arm()
            sw.command(vid).takeoff(10.0)
        sw.step_until(lambda: all(sw.status(v).mode == "hold" for v in FLYERS), 30.0, "up", 12)
        assert sw.radio("uav2") == []  # the behaviours step in offboard mode only
        for vid in FLYERS:
            sw.command(vid).offboard()
        # uav2 hovers on the plume's centreline at x = 20 m, 10 m up: it detects gas at once
        first = sw.wait_radio("uav2", of=Detection, sim_timeout_s=5.0)
        reply = sw.step(240)  # 2 s more of searching
        links = {v: sw.radio_links(v) for v in FLYERS}
        # on return from a step, the tick's batches went through the cache and the callbacks
        assert {v: sw.radio_tick(v) for v in FLYERS} == dict.fromkeys(FLYERS, reply.tick)
        with seen.lock:
            assert len(seen.radio) == sum(len(sw.radio(v)) for v in FLYERS)
        raw.undeclare()
        sub.close()
        fetched_late = _a_late_client_fetches_the_kept_batches(up, sw, "uav2")
        printed = _the_docs_example_on(sw, "agents.md", "### Reading the radio")
        printed_swarm = _the_docs_example_on(sw, "swarm.md", "## Reading the radio")

    dt_s = 1.0 / scenario.time.control_hz
    with seen.lock:
        heard, states, statuses = list(seen.radio), dict(seen.states), list(seen.statuses)
    assert first and all(m.is_a(Detection) and m.sender == "uav2" for m in first)

    # Every detection: where the physics had the vehicle at the detection's tick, published
    # in a step at or after it (within a sensor period and the tick the reading takes).
    detections = [(m, m.decode(Detection)) for m in heard if m.is_a(Detection)]
    assert {m.sender for m, _ in detections} >= {"uav2"}
    for m, d in detections:
        sample_tick = round(d.sim_time_s / dt_s)
        assert math.isclose(sample_tick * dt_s, d.sim_time_s, abs_tol=1e-9), d
        state = states[(m.sender, sample_tick)]
        assert state.sim_time_s == pytest.approx(d.sim_time_s, abs=1e-9)
        assert (d.x_m, d.y_m) == pytest.approx(state.position_enu_m[:2], abs=1e-9), (m, d, state)
        # the reading reaches the behaviour on the tick after its sample: published then
        assert m.tick == sample_tick + 1, (m.tick, sample_tick)
    # the docs' examples printed every kept detection of uav2, and uav1's link counts
    rows = [line.split() for line in printed.splitlines()[:-1]]
    assert rows == [
        ["uav2", str(m.tick), repr(d.x_m), repr(d.y_m), repr(d.sim_time_s)]
        for m, d in detections
        if m.sender == "uav2"
    ]
    assert printed.splitlines()[-1] == repr(links["uav1"])
    assert [line.split() for line in printed_swarm.splitlines()[:-1]] == [r[1:4] for r in rows]
    assert printed_swarm.splitlines()[-1] == repr(links["uav1"])

    # The cache holds what the callbacks got, in (tick, index) order; since_tick and of filter it.
    for vid in FLYERS:
        mine = [m for m in heard if m.sender == vid]
        assert sw.radio(vid) == sorted(mine, key=lambda m: (m.tick, m.index))
        assert sw.radio(vid, Detection, since_tick=reply.tick - 120) == [
            m for m in mine if m.tick > reply.tick - 120 and m.is_a(Detection)
        ]
        assert sw.radio_tick(vid) == reply.tick  # a talking behaviour's batch every tick
    with pytest.raises(RadioReadError, match="is not a VehicleState"):
        detections[0][0].decode(VehicleState)
    assert detections[0][0].decode() == detections[0][1]  # by its kind, imported

    # The link counts are the statuses' of the paused tick, as they crossed the bus.
    for vid in FLYERS:
        last = max((s for s in statuses if s.vehicle_id == vid), key=lambda s: s.sim_time_s)
        assert last.sim_time_s == pytest.approx(reply.sim_time_s, abs=1e-9)
        assert links[vid] == {c.sender: c for c in last.radio}
        assert set(links[vid] or {}) == set(FLYERS) - {vid}
    # Over a radio that loses 30 %, each link's counts are those of the documented model
    # (docs/agents.md; a second implementation, _lost): every tick's state (message 0), every
    # sensor tick's sample (message 1, sent on the tick that collects it, the next), and the
    # sender's messages of the ticks before the paused one (the client's), each lost when
    # its BLAKE2b uniform falls below the loss.
    seed, period = scenario.world.seed, scenario.sensor.period_ticks
    for vid in FLYERS:
        for sender, count in (links[vid] or {}).items():
            sent = [(t, 0) for t in range(reply.tick + 1)]
            sent += [(t + 1, 1) for t in range(0, reply.tick, period)]
            sent += [(m.tick, m.index) for m in heard if m.sender == sender and m.tick < reply.tick]
            lost = sum(_lost(seed, t, sender, vid, index) for t, index in sent)
            assert (count.delivered, count.dropped) == (len(sent) - lost, lost), (sender, vid)
            assert abs(lost / len(sent) - LOSS) <= 4.0 * math.sqrt(LOSS * (1 - LOSS) / len(sent))
    assert fetched_late


def _lost(seed: int, tick: int, sender: str, receiver: str, index: int) -> bool:
    """Whether the radio loses message ``index`` of ``sender`` to ``receiver`` at ``tick``."""
    h = hashlib.blake2b(digest_size=8, person=b"plumeswarm-link")
    h.update(struct.pack("<qqq", seed, tick, index))
    h.update(sender.encode() + b"\x00" + receiver.encode())
    return (int.from_bytes(h.digest(), "little") >> 11) * 2.0**-53 < LOSS


def _the_docs_example_on(sw: Swarm, page: str, heading: str) -> str:
    """What the example under ``heading`` of ``docs/<page>`` prints, run on this client."""
    text = (REPO / "docs" / page).read_text().split(heading, 1)[1]
    code = text.split("```python\n", 1)[1].split("```", 1)[0]
    assert code.count("Swarm.connect()") == 1
    code = code.replace("Swarm.connect()", "_this_client")  # the stack's, not the default's
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, f"docs/{page}", "exec"), {"_this_client": contextlib.nullcontext(sw)})
    return out.getvalue()


def _a_late_client_fetches_the_kept_batches(up: Up, sw: Swarm, vid: str) -> bool:
    """A client that joins now asks the autopilot for the 64 batches it keeps: it then holds
    the first client's messages of those ticks; a vehicle nobody serves is an error."""
    with Swarm.connect(connect=[up.endpoint], command_timeout_s=10.0) as late:
        assert late.radio(vid) == []
        assert late.fetch_radio(vid) == 64
        newest = late.radio_tick(vid)
        assert newest is not None and newest == sw.radio_tick(vid)
        assert late.radio(vid) == sw.radio(vid, since_tick=newest - 64)
        assert late.fetch_radio(vid) == 0  # nothing new the second time
        with pytest.raises(RadioUnavailable, match="uav9"):
            late.fetch_radio("uav9", timeout_s=1.0)
        with pytest.raises(WaitTimeout, match="a radio message from uav9"):
            late.wait_radio("uav9", timeout_s=0.2)
    return True


def test_radio_kept_ticks_is_checked(coop_stack: tuple[Up, Scenario]) -> None:
    with pytest.raises(ValueError, match="radio_kept_ticks must be an integer >= 1, got 0"):
        Swarm.connect(connect=[coop_stack[0].endpoint], radio_kept_ticks=0)


_encode = msgspec.msgpack.Encoder().encode


def _batch(tick: int, *values: float) -> RadioBatch:
    messages = [
        RadioMessage(index=2 + n, kind=kind_of(Detection), payload=_encode(Detection(v, v, v)))
        for n, v in enumerate(values)
    ]
    return RadioBatch(sender="uav1", tick=tick, messages=messages)


def test_the_kept_batches_stay_in_tick_order_and_bounded() -> None:
    kept = RadioKept(ticks=3)
    assert kept.add(_batch(5, 1.0)) is not None and kept.add(_batch(7)) == []  # empty: kept
    assert kept.add(_batch(5, 9.0)) is None  # a tick it has: ignored
    assert kept.add(_batch(6, 2.0, 3.0)) is not None  # late (a query's answer): in its place
    assert [(m.tick, m.index) for m in kept.messages("uav1", -1, None)] == [(5, 2), (6, 2), (6, 3)]
    assert kept.add(_batch(8, 4.0)) is not None  # a fourth tick: the oldest goes
    assert [m.decode(Detection).x_m for m in kept.messages("uav1", -1, None)] == [2.0, 3.0, 4.0]
    assert kept.add(_batch(4, 0.0)) is None  # older than everything a full history keeps
    assert kept.messages("uav1", 6, kind_of(Detection)) == kept.messages("uav1", 7, None)
    assert kept.last_tick("uav1") == 8 and kept.last_tick("uav2") is None
    assert kept.messages("uav1", 6, "other:Type") == []
