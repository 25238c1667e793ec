"""Ticks on the bus (docs/physics.md, Lockstep rule 3; Restarts) on a real Zenoh session: every
tick on sim/tick, the sensor ticks on sim/sensor too, a state only where someone listens."""

from __future__ import annotations

import threading

import msgspec
import zenoh

from sim_world.tick_out import TickOutput
from swarmbus.catchup import RouterOutage
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import SimTick, VehicleState
from tests.support.messages_samples import SAMPLES, STATE
from tests.support.procs import Network, wait_until

KEYS = Keys("tickout")
SENSOR_PERIOD = 4


class Inbox:
    """What a subscriber on ``key`` received, as (key, payload)."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.got: list[tuple[str, bytes]] = []
        self._lock = threading.Lock()
        self.sub = session.declare_subscriber(key, self._on)

    def _on(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.got.append((str(sample.key_expr), sample.payload.to_bytes()))

    def taken(self) -> list[tuple[str, bytes]]:
        with self._lock:
            got, self.got = self.got, []
        return got


def test_ticks_sensor_ticks_states_and_backfill(network: tuple[Network, zenoh.Session]) -> None:
    _, session = network
    ticks, sensor = Inbox(session, KEYS.tick()), Inbox(session, KEYS.sensor_tick())
    state_b = Inbox(session, KEYS.vehicle_state("b"))
    backfill = Inbox(session, KEYS.backfill_of(KEYS.prefix + "/**"))
    out = TickOutput(session, KEYS, ["a", "b"], SENSOR_PERIOD)
    try:
        states = [msgspec.structs.replace(STATE, vehicle_id=v) for v in ("a", "b")]
        out.set(8, b"tick 8", states)
        wait_until(lambda: out.put_states(), 5.0, "a subscriber matched on b's state")
        assert out.states_sent >= 1
        before = out.states_sent
        sent = out.put_states()
        assert sent == [(KEYS.vehicle_state("b"), encode(states[1]))]  # nobody listens to a
        assert out.states_sent == before + 1
        out.put_tick()  # 8: a sensor tick
        out.set(9, b"tick 9", states)
        out.put_tick()
        # each subscriber's callback runs on its own: wait for both keys, not one
        wait_until(
            lambda: len(ticks.got) == 2 and len(sensor.got) >= 1,
            5.0,
            "ticks 8 and 9 on sim/tick, and the sensor tick 8",
        )
        assert [p for _, p in ticks.taken()] == [b"tick 8", b"tick 9"]
        assert [p for _, p in sensor.taken()] == [b"tick 8"]
        assert all(k == KEYS.vehicle_state("b") for k, _ in state_b.taken())
        out.backfill([[(KEYS.tick(), b"tick 8"), *sent]])
        wait_until(lambda: len(backfill.got) == 2, 5.0, "two backfilled samples")
        assert backfill.taken() == [
            (KEYS.backfill_of(KEYS.tick()), b"tick 8"),
            (KEYS.backfill_of(KEYS.vehicle_state("b")), encode(states[1])),
        ]
    finally:
        out.close()
        for inbox in (ticks, sensor, state_b, backfill):
            inbox.sub.undeclare()


def test_states_put_again_for_a_subscriber_back_during_a_router_outage(
    network: tuple[Network, zenoh.Session],
) -> None:
    """Ticks published while nobody subscribed (no state put) reach a subscriber that matches
    again during an outage; the last CATCH_UP_TICKS are kept outside one, every tick during it.
    The re-sent states are put by the output's worker, with the bytes of ``encode(state)``."""
    _, session = network
    out = TickOutput(session, KEYS, ["a"], SENSOR_PERIOD)
    outage = RouterOutage(after_s=3600.0)
    inbox: Inbox | None = None
    try:
        states = {k: [msgspec.structs.replace(STATE, vehicle_id="a", tick=k)] for k in range(400)}
        for k in range(300):  # nobody listens: nothing put; 256 kept
            out.set(k, _tick(k, states[k]), states[k])
            assert out.put_states() == []
            out.catch_up(outage)
        outage.router(False)
        for k in range(300, 400):  # during the outage every tick is kept
            out.set(k, _tick(k, states[k]), states[k])
            out.catch_up(outage)
        inbox = Inbox(session, KEYS.vehicle_state("a"))
        wait_until(lambda: out.put_states(), 5.0, "the subscriber matched")
        wait_until(lambda: inbox.got, 5.0, "tick 399's state, put by put_states")
        assert inbox.taken() == [(KEYS.vehicle_state("a"), encode(states[399][0]))]
        out.catch_up(outage)
        want = [encode(states[k][0]) for k in range(44, 400)]
        wait_until(lambda: len(inbox.got) == len(want), 5.0, "ticks 44..399 again")
        assert [p for _, p in inbox.taken()] == want
        out.catch_up(outage)  # once per return
        assert out.resender.wait_idle(5.0)
        assert out.resender.puts == len(want)
        assert inbox.taken() == []
    finally:
        out.close()
        if inbox is not None:
            inbox.sub.undeclare()


def _tick(tick: int, states: list[VehicleState]) -> bytes:
    """The encoded ``SimTick`` of ``tick`` holding ``states``."""
    base = SAMPLES[SimTick]
    assert isinstance(base, SimTick)
    return encode(msgspec.structs.replace(base, tick=tick, states=states))


def test_what_is_kept_for_a_catch_up_is_bounded_in_bytes(
    network: tuple[Network, zenoh.Session],
) -> None:
    """During an outage the ticks kept stay under the byte bound: the newest ones, as many
    as fit; and a catch-up of many vehicles is handed to the worker, which re-sends the kept
    ticks' states of every vehicle that matched again."""
    _, session = network
    vehicles = [f"v{i}" for i in range(64)]
    bound = 4 * 1024 * 1024
    out = TickOutput(session, KEYS, vehicles, SENSOR_PERIOD, max_kept_bytes=bound)
    outage = RouterOutage(after_s=3600.0)
    inboxes: list[Inbox] = []
    try:
        outage.router(False)
        ticks, sizes = 400, []
        for k in range(ticks):
            states = [msgspec.structs.replace(STATE, vehicle_id=v, tick=k) for v in vehicles]
            payload = _tick(k, states)
            sizes.append(len(payload))
            out.set(k, payload, states)
            out.catch_up(outage)
        # the newest ticks whose sizes sum to at most the bound, counted here from the sizes
        fit, total = 0, 0
        while fit < len(sizes) and total + sizes[-1 - fit] <= bound:
            total += sizes[-1 - fit]
            fit += 1
        assert 0 < fit < ticks
        assert out.kept_bytes == total <= bound
        inboxes = [Inbox(session, KEYS.vehicle_state(v)) for v in vehicles[:2]]

        def both_have_the_last_states() -> bool:
            # the two subscriptions match one at a time: put again until both have had one
            out.put_states()
            return all(i.got for i in inboxes)

        wait_until(both_have_the_last_states, 10.0, "the last tick's states at both subscribers")
        out.catch_up(outage)
        assert out.resender.wait_idle(30.0)
        # a put is not a sample received: after the re-send, an end mark on each key (one
        # session, one key: in order); what came before the re-send is the last tick's states
        for v in vehicles[:2]:
            session.put(KEYS.vehicle_state(v), b"end")
        wait_until(
            lambda: all(i.got and i.got[-1][1] == b"end" for i in inboxes), 10.0, "the end marks"
        )
        for v, inbox in zip(vehicles, inboxes, strict=False):
            got = [p for _, p in inbox.taken()][:-1]
            want = [
                encode(msgspec.structs.replace(STATE, vehicle_id=v, tick=k))
                for k in range(ticks - fit, ticks)
            ]
            assert got[len(got) - fit :] == want
            assert set(got[: len(got) - fit]) == {want[-1]}  # the last tick's, put before
    finally:
        out.close()
        for inbox in inboxes:
            inbox.sub.undeclare()
