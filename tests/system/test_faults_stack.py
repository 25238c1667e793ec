"""SIGKILL one role at a time while three vehicles fly under ``plumeswarm up --headless``; the
supervisor restarts it. Plume: the clock waits for the new service; no reading lost. Gateway:
vehicles unaffected, a MAVLink client hears every vehicle's heartbeat again. Autopilot: the
clock waits for the restarted one, which carries on where it was. Recovery times are printed
(-s)."""

from __future__ import annotations

import itertools
import random
import re
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import psutil
import pytest
import zenoh

from deploy.busview import BusView
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import (
    ActuatorBatch,
    Arm,
    Clock,
    Command,
    CommandReply,
    ConcentrationReading,
    FieldSample,
    FlightMode,
    Message,
    NodeHealth,
    PlumeInfoQuery,
    PlumeMeshQuery,
    PlumeQuery,
    SimTick,
    StepRequest,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.reqrep import NoReply, request
from swarmbus.session import NetworkConfig, open_session
from tests.support.mavclient import MavClient, write_scenario
from tests.support.messages_samples import SAMPLES
from tests.support.procs import keys_for, wait_until
from tests.support.upstack import StackOnBus, plumeswarm_up

VEHICLES = ["uav1", "uav2", "uav3"]
ALTITUDE_M = 40.0


@dataclass
class Stack(StackOnBus):
    readings: list[ConcentrationReading] = field(default_factory=list)
    states: dict[str, VehicleState] = field(default_factory=dict)
    status: dict[str, VehicleStatus] = field(default_factory=dict)

    def pids(self) -> dict[str, int]:
        return self.up.pids()

    def command(self, vid: str, cmd: object) -> CommandReply:
        def ask_once() -> CommandReply | None:  # until its queryable is reachable
            try:
                return request(self.session, self.keys.vehicle_cmd(vid), cmd, CommandReply, 10.0)
            except NoReply:
                return None

        return wait_until(ask_once, 30.0, f"a reply from {vid}")

    def tick_of(self, vid: str) -> int:
        with self.lock:
            return self.states[vid].tick if vid in self.states else -1

    def holding(self, vid: str) -> bool:
        with self.lock:
            s = self.status.get(vid)
        return s is not None and s.mode == FlightMode.HOLD


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("kill")
    scenario, gcs_port, _ = write_scenario(tmp / "scenario.toml", len(VEHICLES))
    with (
        plumeswarm_up(scenario, tmp, "--headless") as up,
        open_session(NetworkConfig(connect=[up.endpoint], listen=[])) as session,
    ):
        keys = keys_for()
        st = Stack(up, session, keys, BusView(session, keys), gcs_port)

        def on_reading(sample: zenoh.Sample) -> None:
            r = decode(sample.payload.to_bytes(), ConcentrationReading)
            with st.lock:
                st.readings.append(r)

        def on_state(sample: zenoh.Sample) -> None:
            s = decode(sample.payload.to_bytes(), VehicleState)
            with st.lock:
                st.states[s.vehicle_id] = s

        def on_status(sample: zenoh.Sample) -> None:
            s = decode(sample.payload.to_bytes(), VehicleStatus)
            with st.lock:
                st.status[s.vehicle_id] = s

        subs = [
            session.declare_subscriber(keys.all_vehicle_concentration(), on_reading),
            session.declare_subscriber(keys.all_vehicle_states(), on_state),
            session.declare_subscriber(keys.all_vehicle_status(), on_status),
        ]
        wait_until(lambda: all(st.tick_of(v) > 1 for v in VEHICLES), 60.0, "ticks")
        for vid in VEHICLES:
            assert st.command(vid, Arm()).accepted
            assert st.command(vid, Takeoff(altitude_m=ALTITUDE_M)).accepted
        wait_until(
            lambda: all(st.states[v].position_enu_m[2] > ALTITUDE_M - 2 for v in VEHICLES),
            240.0,
            "all vehicles at altitude",
            poll_s=0.2,
        )
        # The tests start from a hold: the take-off ends (mode HOLD) only once at altitude, so a
        # test that kills a process right at ALTITUDE_M - 2 would catch a vehicle still climbing.
        wait_until(lambda: all(st.holding(v) for v in VEHICLES), 120.0, "every vehicle holding")
        yield st
        for s in subs:
            s.undeclare()
        st.view.close()


def test_plume_killed_the_clock_waits_and_no_reading_is_lost(stack: Stack) -> None:
    """Lockstep: the plume is a participant of the sensor ticks; the physics holds the clock
    while the launcher restarts it, and the new service answers the held sensor tick: no
    reading unavailable, none missing."""
    wait_until(lambda: any(r.available for r in stack.readings[-10:]), 60.0, "an available reading")
    start = len(stack.readings)
    _, restart_s, _ = stack.up.kill("plume")
    t0 = time.monotonic()
    wait_until(
        lambda: sum(r.available for r in stack.readings[start:]) > 60 * len(VEHICLES),
        90.0,
        "readings after the plume restart",
        poll_s=0.1,
    )
    back_s = time.monotonic() - t0 + restart_s
    with stack.lock:
        during = stack.readings[start:]
    gaps = [r for r in during if not r.available]
    assert not gaps, f"{len(gaps)} readings unavailable, e.g. {gaps[0]}"
    for vid in VEHICLES:
        times = sorted({r.sim_time_s for r in during if r.vehicle_id == vid})
        steps = [b - a for a, b in itertools.pairwise(times)]
        assert steps and max(steps) < 1.5 * min(steps), (vid, min(steps), max(steps))
    log = (stack.up.run / "physics.log").read_text()
    print(f"plume: restarted in {restart_s:.1f} s, {len(during)} readings since the kill "
          f"({back_s:.1f} s), none unavailable or missing; physics held the clock for it: "
          f"{'holding the clock for plume' in log}")  # fmt: skip


def test_gateway_killed_clients_see_every_vehicle_again(stack: Stack) -> None:
    with MavClient(stack.gcs_port) as gcs:
        # no GCS heartbeat of ours: its loss when the client closes would (rightly) trigger
        # the vehicles' datalink failsafe and mix that into the autopilot test below
        for sysid in (1, 2, 3):
            gcs.wait_type("HEARTBEAT", sysid, timeout_s=60.0)
        ticks = {v: stack.tick_of(v) for v in VEHICLES}
        _, restart_s, _ = stack.up.kill("gateway")
        t0 = time.monotonic()
        gcs.log.clear()
        for sysid in (1, 2, 3):
            gcs.wait_type("HEARTBEAT", sysid, timeout_s=90.0)
        back_s = time.monotonic() - t0 + restart_s
    # the vehicles flew on: ticks advanced and they are still up there
    assert all(stack.tick_of(v) > ticks[v] for v in VEHICLES)
    assert all(stack.states[v].position_enu_m[2] > ALTITUDE_M - 3 for v in VEHICLES)
    print(f"gateway: restarted in {restart_s:.1f} s, heartbeats of all 3 back after {back_s:.1f} s")


FUZZ_SECONDS = 40.0


def _mutate(rng: random.Random, data: bytes) -> bytes:
    """Random bytes, or ``data`` truncated, bit-flipped, spliced or extended."""
    b = bytearray(data)
    how = rng.randrange(6)
    if how == 0 or not b:
        return rng.randbytes(rng.randrange(0, 200))
    if how == 1:
        return bytes(b[: rng.randrange(len(b))])
    if how == 2:
        for _ in range(rng.randint(1, 8)):
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
        return bytes(b)
    if how == 3:
        i = rng.randrange(len(b))
        return bytes(b[:i] + rng.randbytes(rng.randint(1, 20)) + b[i:])
    if how == 4:
        i, j = sorted(rng.randrange(len(b)) for _ in range(2))
        return bytes(b[:i] + b[j:] + b[i:j])
    return bytes(b) + rng.randbytes(rng.randint(1, 50))


def fuzz_targets(
    keys: Keys,
) -> tuple[list[tuple[str, type[Message] | None]], list[tuple[str, Any]]]:
    """Every publication key with its own message type (None: no decode check), and every query
    key with the type it decodes."""
    topics: list[tuple[str, type[Message] | None]] = [
        (keys.tick(), SimTick),
        (keys.sensor_tick(), SimTick),
        (keys.clock(), Clock),
        (keys.node_health("physics"), NodeHealth),
        (keys.plume_info(), None),
        (keys.plume_sample(), FieldSample),
    ]
    for v in VEHICLES:
        topics += [
            (keys.vehicle_state(v), VehicleState),
            (keys.autopilot_actuators(autopilot_node(v)), ActuatorBatch),
            (keys.vehicle_status(v), VehicleStatus),
            (keys.vehicle_concentration(v), ConcentrationReading),
        ]
    queries: list[tuple[str, Any]] = [
        (keys.plume_concentration(), PlumeQuery),
        (keys.plume_info(), PlumeInfoQuery),
        (keys.plume_mesh(), PlumeMeshQuery),
        (keys.clock_step(), StepRequest),  # a lockstep world: refused, says why
        *[(keys.vehicle_cmd(v), Command) for v in VEHICLES],
    ]
    return topics, queries


def test_fuzz_every_bus_key_while_flying(stack: Stack) -> None:
    """Random and mutated payloads on every key (publications and queries) while the vehicles
    hold: no process dies or restarts, the flight goes on. A mutated payload that still decodes
    as the key's own message type is not sent on control keys (that is a valid command or
    state, not garbage: keeping strangers off the bus is the access control's job)."""
    keys, rng = stack.keys, random.Random(9)
    samples = list(SAMPLES.values())
    topics, queries = fuzz_targets(keys)

    def garbage(own: type[Message] | None) -> bytes:
        while True:
            data = _mutate(rng, encode(rng.choice(samples)))
            if own is None:
                return data
            try:
                decode(data, own)
            except MessageError:
                return data

    pids = stack.pids()
    ticks = {v: stack.tick_of(v) for v in VEHICLES}
    publishers = {k: stack.session.declare_publisher(k) for k, _ in topics}
    sent = asked = 0
    deadline = time.monotonic() + FUZZ_SECONDS
    while time.monotonic() < deadline:
        for _ in range(200):
            key, own = rng.choice(topics)
            publishers[key].put(garbage(own))
            sent += 1
        key, own = rng.choice(queries)
        for _ in stack.session.get(key, payload=garbage(own), timeout=2.0):
            pass
        asked += 1
    for p in publishers.values():
        p.undeclare()
    wait_until(lambda: all(stack.tick_of(v) > ticks[v] + 50 for v in VEHICLES), 60.0, "ticks go on")
    assert stack.up.proc.poll() is None
    assert stack.pids() == pids, "a process was restarted"
    assert all(psutil.pid_exists(p) for p in pids.values())
    for v in VEHICLES:
        assert stack.states[v].position_enu_m[2] > ALTITUDE_M - 3, v
        assert stack.status[v].mode == FlightMode.HOLD and stack.status[v].armed, v
    # Every receiver of a fuzzed key said what it refused, as the type it expected there: the
    # physics (actuators, health, plume samples), the plume (sensor ticks, its queries), each
    # autopilot (ticks, its commands), the gateway (states in ticks, statuses, readings).
    receivers = ["physics", "plume", "gateway", *[autopilot_node(v) for v in VEHICLES]]
    assert set(receivers) == set(pids) - {"router"}, sorted(pids)
    rejections = {n: _typed_rejections((stack.up.run / f"{n}.log").read_text()) for n in receivers}
    counts = {n: len(r) for n, r in rejections.items()}
    print("fuzz: typed rejections logged: " + ", ".join(f"{n} {c}" for n, c in counts.items()))
    assert all(counts.values()), counts
    print(f"fuzz: {sent} publications and {asked} queries in {FUZZ_SECONDS:.0f} s, "
          "no process died, the vehicles held")  # fmt: skip


# a refusal naming the message type it expected (``swarmbus.codec.MessageError``)
_TYPED = re.compile(r" WARNING: .*\binvalid [A-Z][A-Za-z]+\b")


def _typed_rejections(log_text: str) -> list[str]:
    """The lines of a process log that refuse a payload as not of its expected type."""
    return [line for line in log_text.splitlines() if _TYPED.search(line)]


def test_autopilot_killed_midflight_the_clock_waits_and_it_flies_on(stack: Stack) -> None:
    """Lockstep: the physics holds the clock while the launcher restarts the autopilot, which
    restores the state of the tick before: uav1 never drops, keeps holding, nobody moves on
    without it (the bit-for-bit comparison with a run without the kill is
    test_faults_resume.py)."""
    z0 = stack.states["uav1"].position_enu_m[2]
    _, restart_s, _ = stack.up.kill("autopilot-uav1")
    t0 = time.monotonic()
    ticks = {v: stack.tick_of(v) for v in VEHICLES}
    wait_until(
        lambda: all(stack.tick_of(v) > ticks[v] + 20 for v in VEHICLES),
        90.0,
        "the lockstep to go on with the restarted autopilot",
    )
    back_s = time.monotonic() - t0 + restart_s
    log = (stack.up.run / "physics.log").read_text()
    assert "holding the clock for uav1: autopilot-uav1 is being restarted" in log
    assert "dropped uav1" not in log
    assert "restored the state of tick" in (stack.up.run / "autopilot-uav1.log").read_text()
    with stack.lock:
        s = stack.status["uav1"]
    assert s.armed and s.mode == FlightMode.HOLD and not s.crashed
    assert not s.failsafe.startswith("autopilot restarted"), s.failsafe
    assert abs(stack.states["uav1"].position_enu_m[2] - z0) < 1.0
    for v in ("uav2", "uav3"):
        assert stack.states[v].position_enu_m[2] > ALTITUDE_M - 3
        assert stack.status[v].mode == FlightMode.HOLD
    print(f"autopilot: restarted in {restart_s:.1f} s, ticks again after {back_s:.1f} s; "
          f"uav1 held at {z0:.1f} m, nothing dropped")  # fmt: skip
