"""The autopilot process on a real Zenoh network, driven by a lockstep stand-in for physics.

The physics process is replaced by :class:`tests.support.toy_physics.BusToyPhysics` (the agreed
tick / actuator protocol over toy dynamics); the plume service is the real process.
"""

from __future__ import annotations

import contextlib
import re
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import msgspec
import numpy as np
import pytest
import zenoh

from agents import CommandRejected, Swarm, WaitTimeout
from agents.autopilot_node import AutopilotNode
from agents.build import AutopilotOptions
from agents.node_events import Inbox, TickArrived
from plume_service import GaussianPlume
from swarmbus.codec import MessageError, decode, encode
from swarmbus.messages import (
    ConcentrationReading,
    ErrorReply,
    FlightMode,
    RejectCode,
    SimTick,
    VehicleStatus,
)
from swarmbus.node import NodeContext
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario
from swarmbus.session import NetworkConfig, Presence, open_session
from tests.support.messages_samples import STATE as STATE_SAMPLE
from tests.support.procs import Network, NodeProcs, keys_for
from tests.support.toy_physics import BusToyPhysics


@pytest.fixture
def swarm(network: tuple[Network, zenoh.Session]) -> Iterator[Swarm]:
    net, _ = network
    with Swarm.connect(connect=[net.endpoint], command_timeout_s=5.0) as sw:
        yield sw


def start_autopilots(procs: NodeProcs, sw: Swarm, ids: list[str]) -> None:
    for vid in ids:
        procs.start("autopilot", "--vehicle", vid)
    sw.wait_until(lambda: set(ids) <= set(sw.vehicles), 30.0, f"autopilot tokens of {ids}")


@pytest.fixture
def procs(network: tuple[Network, zenoh.Session]) -> Iterator[NodeProcs]:
    """Node processes on the test network, flying the default scenario."""
    net, _ = network
    with NodeProcs(net, DEFAULT_SCENARIO) as started:
        yield started


def toy_physics(
    network: tuple[Network, zenoh.Session], participants: list[str], plume: bool = False
) -> BusToyPhysics:
    """The lockstep stand-in for physics on the router's session, over the default scenario."""
    return BusToyPhysics(network[1], load_scenario(), participants=participants, plume=plume)


def test_one_vehicle_over_the_bus_with_the_plume_service(
    network: tuple[Network, zenoh.Session], swarm: Swarm, tmp_path: Path
) -> None:
    net, router = network
    with NodeProcs(net, DEFAULT_SCENARIO, tmp_path) as procs:
        procs.start("plume")
        start_autopilots(procs, swarm, ["uav2"])
        uav = swarm.command("uav2")
        with pytest.raises(CommandRejected, match="no vehicle state yet"):
            uav.arm()
        # garbage on the command queryable: an ErrorReply, and the process lives on (raw on
        # purpose: the ErrorReply on the wire is what this checks)
        replies = list(
            router.get(keys_for().vehicle_cmd("uav2"), payload=b"\x93garbage", timeout=5)
        )
        assert replies and replies[0].err is not None
        assert decode(replies[0].err.payload.to_bytes(), ErrorReply).reason
        with toy_physics(network, ["uav2"], plume=True) as physics:
            swarm.wait_until(lambda: swarm.state("uav2"), 10.0, "uav2 state")
            uav.arm()
            uav.takeoff(10.0)
            swarm.wait_until(lambda: swarm.status("uav2").mode == FlightMode.HOLD, 60, "hover")
            with pytest.raises(CommandRejected) as info:
                uav.takeoff(5.0)
            assert info.value.code == RejectCode.DENIED and "already flying" in info.value.reason
            readings: list[ConcentrationReading] = []
            sub = swarm.subscribe(on_reading=readings.append)
            uav.goto(30.0, 0.0, 10.0)
            swarm.wait_until(lambda: len(readings) > 300, 60, "300 readings")
            sub.close()
            uav.land()
            swarm.wait_until(lambda: not swarm.status("uav2").armed, 60, "landed and disarmed")
        assert physics.error is None, physics.error
        assert all(p.poll() is None for _, p in procs.procs), "a node died"
    plume = GaussianPlume.preset("novak2018")
    pos = np.array([r.position_enu_m for r in readings])
    truth = plume.concentration(pos)
    assert all(r.available for r in readings)
    np.testing.assert_allclose(
        np.array([r.true_g_m3 for r in readings], float), truth, rtol=1e-9, atol=0
    )
    window = np.where(truth < 0.01, 0.0, np.minimum(truth, 0.2))
    np.testing.assert_allclose(
        np.array([r.reported_g_m3 for r in readings], float), window, rtol=1e-9, atol=0
    )
    assert ((window > 0.01) & (window < 0.2)).any()  # some readings inside the window
    peers = readings[-1].peers
    assert {p.vehicle_id for p in peers} == {"uav1", "uav3"}
    np.testing.assert_allclose(
        [p.true_g_m3 for p in peers],
        plume.concentration([p.position_enu_m for p in peers]),
        rtol=1e-9,
    )


def test_without_a_plume_service_readings_are_unavailable_never_zero(
    network: tuple[Network, zenoh.Session], swarm: Swarm, procs: NodeProcs
) -> None:
    start_autopilots(procs, swarm, ["uav1"])
    with toy_physics(network, ["uav1"]):
        swarm.wait_until(lambda: swarm.reading("uav1"), 30.0, "a reading")
        r = swarm.reading("uav1")
        assert r is not None and not r.available
        assert r.reported_g_m3 is None and r.true_g_m3 is None
        swarm.wait_until(
            lambda: "plume service" in swarm.status("uav1").health, 10.0, "sensor health"
        )


def test_one_process_serves_several_vehicles_with_one_token_each(
    network: tuple[Network, zenoh.Session], swarm: Swarm, procs: NodeProcs
) -> None:
    procs.start("autopilot", "--vehicle", "uav1", "--vehicle", "uav3")
    presence = Presence(network[1], keys_for())
    assert presence.wait_for(lambda alive: {"autopilot-uav1", "autopilot-uav3"} <= alive, 30.0), (
        sorted(presence.alive)
    )
    presence.close()
    with toy_physics(network, ["uav1", "uav3"]) as physics:
        swarm.wait_until(lambda: swarm.state("uav3"), 10.0, "uav3 state")
        for vid in ("uav1", "uav3"):
            swarm.command(vid).arm()
            swarm.command(vid).takeoff(3.0)
        swarm.wait_until(
            lambda: all(swarm.status(v).mode == FlightMode.HOLD for v in ("uav1", "uav3")),
            60,
            "both hovering",
        )
    assert physics.error is None


def test_wait_until_names_what_did_not_happen(swarm: Swarm) -> None:
    with pytest.raises(WaitTimeout, match="waiting for the impossible"):
        swarm.wait_until(lambda: False, 0.1, "the impossible")


def test_command_to_a_missing_vehicle_times_out(swarm: Swarm) -> None:
    from agents import CommandTimeout

    swarm.command_timeout_s = 0.3
    with pytest.raises(CommandTimeout, match="autopilot-ghost"):
        swarm.command("ghost").arm()


def test_invalid_payload_values_are_rejected_by_the_decoder(swarm: Swarm, procs: NodeProcs) -> None:
    start_autopilots(procs, swarm, ["uav1"])
    with pytest.raises(CommandRejected) as info:
        swarm.command("uav1").goto(float("nan"), 0.0, 5.0)
    assert info.value.code == RejectCode.INVALID and "position_enu_m" in info.value.field
    assert procs.procs[0][1].poll() is None


def test_a_garbage_sample_behind_a_real_tick_does_not_push_it_out_of_the_inbox() -> None:
    """Ticks that pile up are handed out newest only; a sample on ``sim/tick`` that is no tick
    (garbage, a stranger's put) must not be the "newest" that replaces the real one, or the
    physics would wait for an answer that never comes."""
    real = encode(SimTick(tick=7, sim_time_s=7 / 120, control_dt_s=1 / 120, states=[]))
    inbox: Inbox[TickArrived] = Inbox()
    inbox.put(TickArrived(real))
    inbox.put(TickArrived(b"\x92\x01garbage"))
    first = next(inbox.events(threading.Event()))
    assert isinstance(first, TickArrived) and first.data == real


def test_a_tick_going_back_counts_only_if_it_is_a_whole_sim_tick(tmp_path: Path) -> None:
    """A tick number below the last is a physics resumed from its checkpoint, and the node
    rewinds to it. A sample that only looks like such a tick (its own state decodes, the rest is
    mangled: here ``control_dt_s``) is garbage, not a resume: the node must not fly the state it
    carries. Real session (loopback, no peers), the node's own tick handler."""
    scenario = load_scenario(DEFAULT_SCENARIO)
    own = STATE_SAMPLE
    ctx = NodeContext(
        scenario=scenario,
        network=NetworkConfig(connect=[], listen=[]),
        name="autopilot-uav1",
        vehicle_ids=("uav1",),
    )

    def tick_bytes(tick: int, control_dt_s: float) -> bytes:
        fields = msgspec.to_builtins(
            SimTick(tick=tick, sim_time_s=tick / 120, control_dt_s=1 / 120, states=[own])
        )
        fields["control_dt_s"] = control_dt_s
        return msgspec.msgpack.encode(fields)

    with open_session(ctx.network) as session:
        node = AutopilotNode(session, ctx, AutopilotOptions())
        try:
            node._on_tick_data(tick_bytes(100, 1 / 120))
            assert node.last_tick == 100
            mangled = tick_bytes(42, -1.0)
            with pytest.raises(MessageError):
                decode(mangled, SimTick)
            node._on_tick_data(mangled)
            assert node.last_tick == 100, "a mangled tick rewound the node"
            node._on_tick_data(tick_bytes(42, 1 / 120))  # a real resume still rewinds
            assert node.last_tick == 42
        finally:
            node.close()


def _toy_flight_paused(
    network: tuple[Network, zenoh.Session], swarm: Swarm, tmp_path: Path, mode: str
) -> tuple[float, VehicleStatus, str]:
    """uav1 holding at 10 m over the toy physics; the ticks stop for 4 s (wall), then go on
    until it is disarmed or 20 s passed. The status seen 4 s into the pause, and the log."""
    net, router = network
    scenario_file = tmp_path / f"{mode}.toml"
    text = DEFAULT_SCENARIO.read_text()
    scenario_file.write_text(text.replace('mode = "lockstep"', f'mode = "{mode}"', 1))
    sc = load_scenario(scenario_file)
    with NodeProcs(net, scenario_file, tmp_path) as procs:
        start_autopilots(procs, swarm, ["uav1"])
        with BusToyPhysics(router, sc, participants=["uav1"]) as physics:
            uav = swarm.command("uav1")
            swarm.wait_until(lambda: swarm.state("uav1"), 10.0, "uav1 state")
            uav.arm()
            uav.takeoff(10.0)
            swarm.wait_until(lambda: swarm.status("uav1").mode == FlightMode.HOLD, 60, "hover")
            physics.pause()
            paused_at = time.monotonic()
            time.sleep(4.0)  # the state-loss timeout is 3 s
            during = swarm.status("uav1")
            assert during is not None
            landed_at = 0.0
            with contextlib.suppress(WaitTimeout):
                swarm.wait_until(
                    lambda: (s := swarm.status("uav1")) is not None and s.mode == FlightMode.LAND,
                    5.0,
                    "LAND",
                )
                landed_at = time.monotonic() - paused_at
            physics.resume()
            with contextlib.suppress(WaitTimeout):
                swarm.wait_until(lambda: not swarm.status("uav1").armed, 20.0, "disarmed")
        assert physics.error is None, physics.error
    return landed_at, during, (tmp_path / "autopilot-uav1.log").read_text()


def test_realtime_without_ticks_for_the_state_loss_timeout_the_autopilot_lands(
    network: tuple[Network, zenoh.Session], swarm: Swarm, tmp_path: Path
) -> None:
    landed_at, during, log = _toy_flight_paused(network, swarm, tmp_path, "realtime")
    timeout_s = load_scenario().failsafe.state_loss_timeout_s
    assert during.mode == FlightMode.LAND, during
    assert during.failsafe.startswith("vehicle state lost: no tick for"), during.failsafe
    assert landed_at >= timeout_s
    assert re.search(r"uav1: no tick for [0-9.]+ s after tick \d+: vehicle state lost", log)
    assert re.search(r"ticks again after [0-9.]+ s without: tick \d+ after tick \d+", log)
    final = swarm.status("uav1")
    assert final is not None and not final.armed and final.mode == FlightMode.DISARMED


def test_lockstep_without_ticks_the_autopilot_waits_in_its_mode(
    network: tuple[Network, zenoh.Session], swarm: Swarm, tmp_path: Path
) -> None:
    """In lockstep the physics holds the clock: ticks that stop are no lost state."""
    _, during, log = _toy_flight_paused(network, swarm, tmp_path, "lockstep")
    assert during.mode == FlightMode.HOLD and during.failsafe == "", during
    assert "vehicle state lost" not in log
    final = swarm.status("uav1")
    assert final is not None and final.mode == FlightMode.HOLD and final.armed
