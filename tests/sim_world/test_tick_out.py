"""Ticks on the bus (docs/physics.md, Lockstep rule 3; Restarts) on a real Zenoh session: every
tick on sim/tick, the sensor ticks on sim/sensor too, a state only where someone listens."""

from __future__ import annotations

import threading

import msgspec
import zenoh

from sim_world.tick_out import TickOutput
from swarmbus.codec import encode
from swarmbus.keys import Keys
from tests.support.messages_samples import STATE
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
        wait_until(lambda: len(ticks.got) == 2, 5.0, "ticks 8 and 9 on sim/tick")
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
