"""The gateway takes vehicle states from ``sim/tick`` (one message per tick, as the physics
publishes it; the per-vehicle ``vehicle/<id>/state`` puts are not needed) and decodes a
vehicle's state only where its telemetry falls due: a broken state is skipped and the stream
goes out at the next tick, a restarted simulation restarts the streams."""

from __future__ import annotations

import random
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh

from gcs_bridge.dialect import mavlink
from gcs_bridge.gateway import Gateway
from gcs_bridge.options import GatewayOptions
from gcs_bridge.telemetry import StreamSchedule
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import SimTick, VehicleState
from swarmbus.scenario import load_scenario
from swarmbus.session import open_session
from tests.support.mavclient import MavClient, write_scenario
from tests.support.messages_samples import reading, vehicle_state
from tests.support.procs import Network

DT = 1.0 / 120.0
IDS = ["uav1", "uav2"]


def test_schedule_window_is_exactly_where_wants_is_false() -> None:
    rng = random.Random(3)
    ids = [int(mavlink.MAVLINK_MSG_ID_ATTITUDE), int(mavlink.MAVLINK_MSG_ID_VFR_HUD)]
    sched = StreamSchedule({ids[0]: 10.0, ids[1]: 4.0})
    t = 0.0
    for _ in range(3000):
        op = rng.random()
        if op < 0.02:
            sched.set_interval_us(rng.choice(ids), rng.choice([-1.0, 0.0, 20_000.0, 1e6]))
        elif op < 0.03:
            t = rng.uniform(0.0, t)  # a restart
        else:
            t += rng.choice([DT, DT, DT, 0.5, 1e-7])
        probe = t + rng.choice([0.0, -1e-6, 1e-9, -2e-6, DT])
        inside = sched.lo - 1e-6 <= probe < sched.hi - 1e-9
        assert sched.wants(probe) is not inside
        if rng.random() < 0.7:
            sched.due(t)


def state(vid: str, k: int, lat: float = 47.4) -> VehicleState:
    return vehicle_state(
        vid, k, (0.01 * k, 0.0, 1.0), sim_time_s=k * DT, velocity_enu_m_s=(1.2, 0.0, 0.0),
        lat_deg=lat, lon_deg=8.5,
    )  # fmt: skip


def wait_matched(pub: zenoh.Publisher, timeout_s: float) -> None:
    """Until a subscriber matches ``pub`` (then a put reaches it), at most ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        status: Any = pub.matching_status  # a MatchingStatus (the stub says bool)
        if status.matching:
            return
        assert time.monotonic() < deadline, "no subscriber matched the tick publisher"
        time.sleep(0.01)


@contextmanager
def fed_by_ticks(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> Iterator[tuple[Gateway, Keys, int, zenoh.Publisher]]:
    """A gateway (no API links) whose vehicles' autopilots are alive (the test session's tokens)
    and whose ticks come from the test's publisher, matched: the gateway, keys, GCS port and
    publisher."""
    net, session = network
    path, gcs_port, _ = write_scenario(tmp_path / "sc.toml", len(IDS), telemetry_hz=10.0)
    scenario = load_scenario(path)
    keys = Keys(scenario.world.name)
    options = GatewayOptions(telemetry_hz=scenario.gateway.telemetry_hz, api_links=False)
    tokens = [session.liveliness().declare_token(keys.node_health(f"autopilot-{v}")) for v in IDS]
    pub = session.declare_publisher(keys.tick())
    try:
        with (
            open_session(net.client) as gw_session,
            Gateway(scenario, options, IDS, gw_session, keys) as gw,
        ):
            assert gw._presence is not None
            assert gw._presence.wait_for(lambda a: {f"autopilot-{v}" for v in IDS} <= a, 30.0)
            wait_matched(pub, 30.0)  # the gateway's tick subscription reached the publisher
            yield gw, keys, gcs_port, pub
    finally:
        for t in tokens:
            t.undeclare()


def test_states_come_from_ticks_only(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    with (
        fed_by_ticks(network, tmp_path) as (gw, _, gcs_port, pub),
        MavClient(gcs_port) as client,
    ):

        def run(ticks: range, broken: int) -> None:
            for k in ticks:
                states = [
                    state(v, k, lat=1000.0 if (v, k) == ("uav1", broken) else 47.4) for v in IDS
                ]
                pub.put(encode(SimTick(tick=k, sim_time_s=k * DT, control_dt_s=DT, states=states)))
                gw.poll(0.0)
                time.sleep(0.002)
            deadline = time.monotonic() + 2.0
            while time.monotonic() < deadline:
                gw.poll(0.01)
                client.pump(0.0)

        run(range(1, 121), broken=60)  # uav1's state of tick 60 (due at 0.5 s) is invalid
        times = {
            s: [m.time_boot_ms for m in client.logged("GLOBAL_POSITION_INT", s)] for s in (1, 2)
        }
        assert times[2][:6] == [8, 108, 208, 308, 408, 508], times[2]
        assert 500 not in times[1] and 508 in times[1], times[1]  # the next tick's state went out
        assert len(times[1]) == len(times[2]) >= 10
        last = gw.vehicles["uav1"].state  # decoded when read: the newest tick's
        assert last is not None and last.tick == 120
        pos = client.logged("GLOBAL_POSITION_INT", 2)[-1]
        assert pos.vx == 0 and pos.vy == 120  # 1.2 m/s east = NED y, cm/s

        # garbage on sim/tick (a non-UTF-8 vehicle id in a new layout, a tick that is no
        # tick) is logged and skipped; the gateway goes on
        ok = encode(state("uav2", 121))
        bad_id = ok.replace(b"uav2", b"\xff\xfe\xfd\xfc")
        assert bad_id != ok
        bad_tick = {"schema": "sim_tick/v1", "tick": 121, "sim_time_s": 1.0, "control_dt_s": DT}
        for payload in (
            b"\x93garbage",
            encode(SimTick(tick=121, sim_time_s=1.0, control_dt_s=DT, states=[])),
            encode({**bad_tick, "states": [msgspec.Raw(bad_id)]}),
        ):
            pub.put(payload)
        for _ in range(20):
            gw.poll(0.01)

        client.log.clear()
        run(range(0, 30), broken=-1)  # a new simulation: the streams start again
        again = [m.time_boot_ms for m in client.logged("GLOBAL_POSITION_INT", 1)]
        assert again[:3] == [0, 100, 200], again


@pytest.mark.skipif(sys.platform != "linux", reason="refusals are read with Linux's IP_RECVERR")
def test_a_ground_station_that_comes_late_gets_the_newest_telemetry(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    """Nobody listens on the GCS port at first (the kernel refuses what the gateway sends), so
    the gateway builds no telemetry and takes no readings; a ground station that starts
    listening mid-run gets the newest state, and readings again."""
    _, session = network
    k = 0
    with fed_by_ticks(network, tmp_path) as (gw, keys, gcs_port, pub):
        reading_pub = session.declare_publisher(keys.vehicle_concentration("uav1"))
        wait_matched(reading_pub, 30.0)

        def step() -> None:
            nonlocal k
            k += 1
            states = [state(v, k) for v in IDS]
            pub.put(encode(SimTick(tick=k, sim_time_s=k * DT, control_dt_s=DT, states=states)))
            gw.poll(0.005)

        def matched() -> bool:
            status: Any = reading_pub.matching_status
            return bool(status.matching)

        deadline = time.monotonic() + 30.0
        while gw.links.listened(time.monotonic()) or matched():
            assert time.monotonic() < deadline, (
                f"still listened: {gw.links.listened(time.monotonic())}, "
                f"readings still wanted: {matched()}"
            )
            step()
        for _ in range(60):
            step()
        bound_at = k
        with MavClient(gcs_port) as client:

            def got(kind: str, sysid: int) -> list[Any]:
                client.pump(0.0)
                return client.logged(kind, sysid)

            deadline = time.monotonic() + 30.0
            while not (got("GLOBAL_POSITION_INT", 1) and got("GLOBAL_POSITION_INT", 2)):
                assert time.monotonic() < deadline, "no telemetry for the late ground station"
                step()
            for sysid in (1, 2):
                pos = got("GLOBAL_POSITION_INT", sysid)[0]
                sent_at = round(pos.time_boot_ms / (1000.0 * DT))
                assert bound_at < sent_at <= k, (bound_at, pos.time_boot_ms, k)
                assert pos.time_boot_ms == int(sent_at * DT * 1000.0)
                assert pos.vx == 0 and pos.vy == 120  # 1.2 m/s east = NED y, cm/s
                assert pos.lat == 474_000_000 and pos.lon == 85_000_000

            wait_matched(reading_pub, 30.0)  # the gateway takes readings again
            sent = reading("uav1", k * DT, (0.0, 0.0, 1.0), 0.125)
            reading_pub.put(encode(sent))
            deadline = time.monotonic() + 30.0
            while not got("NAMED_VALUE_FLOAT", 1):
                assert time.monotonic() < deadline, "no reading for the late ground station"
                step()
            value = got("NAMED_VALUE_FLOAT", 1)[0]
            assert value.time_boot_ms == int(sent.sim_time_s * 1000.0)
            assert abs(value.value - 0.125) < 1e-6
