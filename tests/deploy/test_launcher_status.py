"""``plumeswarm status`` against a bus where stand-ins publish what physics and an autopilot do."""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

import msgspec
import zenoh

from swarmbus.codec import encode
from swarmbus.messages import (
    Clock,
    FlightMode,
    LinkStatus,
    SpeedMode,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import load_scenario
from tests.support.messages_samples import reading, vehicle_state, vehicle_status
from tests.support.procs import Network, repeating, run_cli


def state(vid: str, x: float) -> VehicleState:
    return vehicle_state(vid, 240, (x, 1.0, 10.0), sim_time_s=2.0)


@contextmanager
def stand_ins(net: Network, radio: list[LinkStatus] | None = None) -> Iterator[None]:
    """A 'physics' and an 'autopilot-uav1' node publishing until the block ends (``radio``:
    uav1's status carries these link counts)."""
    sc = load_scenario()
    with ExitStack() as stack:
        phys = stack.enter_context(
            NodeRuntime(NodeContext(sc, net.client, "physics"), "physics", install_signals=False)
        )
        ap = stack.enter_context(
            NodeRuntime(
                NodeContext(sc, net.client, "autopilot-uav1", ("uav1",)),
                "autopilot",
                install_signals=False,
            )
        )
        phys.ready()
        ap.ready()
        keys = phys.keys

        clock = Clock(
            tick=240,
            sim_time_s=2.0,
            mode=SpeedMode.LOCKSTEP,
            speed_factor=1.0,
            real_time_factor=7.5,
        )
        status = vehicle_status(sim_time_s=2.0, mode=FlightMode.MISSION, armed=True, landed=False)
        if radio is not None:
            status = msgspec.structs.replace(status, radio=radio)

        def publish() -> None:
            phys.session.put(keys.clock(), encode(clock))
            for i, vid in enumerate(v.id for v in sc.vehicles):
                phys.session.put(keys.vehicle_state(vid), encode(state(vid, 20.0 + i)))
            ap.session.put(keys.vehicle_status("uav1"), encode(status))
            ap.session.put(
                keys.vehicle_concentration("uav1"),
                encode(reading("uav1", 2.0, (20.0, 1.0, 10.0), 0.05)),
            )

        stack.enter_context(repeating(0.05, publish))
        yield


def test_status_json_has_the_documented_shape(network: tuple[Network, zenoh.Session]) -> None:
    net, _ = network
    with stand_ins(net):
        result = run_cli(["status", "--json", "--connect", net.endpoint, "--timeout", "20"])
    assert result.returncode == 0, result.stderr
    data = json.loads(result.stdout)
    assert set(data) == {"sim_time", "real_time_factor", "nodes", "vehicles"}
    assert data["sim_time"] == 2.0 and data["real_time_factor"] == 7.5
    nodes = {n["name"]: n for n in data["nodes"]}
    assert {"physics", "autopilot-uav1"} <= set(nodes)
    assert nodes["physics"]["pid"] == os.getpid() and nodes["physics"]["host"]
    assert nodes["autopilot-uav1"]["role"] == "autopilot"
    uav1 = data["vehicles"]["uav1"]
    assert uav1 == {
        "mode": "mission",
        "armed": True,
        "position": [20.0, 1.0, 10.0],
        "reading": 0.05,
    }
    assert data["vehicles"]["uav3"]["position"] == [22.0, 1.0, 10.0]


def test_status_json_shows_what_each_radio_link_carried(
    network: tuple[Network, zenoh.Session],
) -> None:
    net, _ = network
    links = [
        LinkStatus(sender="uav2", delivered=70, dropped=30),
        LinkStatus(sender="uav3", delivered=68, dropped=32),
    ]
    with stand_ins(net, links):
        result = run_cli(["status", "--json", "--connect", net.endpoint, "--timeout", "20"])
    assert result.returncode == 0, result.stderr
    uav1 = json.loads(result.stdout)["vehicles"]["uav1"]
    assert uav1["radio"] == {
        "uav2": {"delivered": 70, "dropped": 30},
        "uav3": {"delivered": 68, "dropped": 32},
    }
    assert uav1["mode"] == "mission"


def test_status_text_lists_nodes_and_vehicles(network: tuple[Network, zenoh.Session]) -> None:
    net, _ = network
    with stand_ins(net):
        result = run_cli(["status", "--connect", net.endpoint, "--timeout", "20"])
    assert result.returncode == 0, result.stderr
    assert "real-time factor 7.50x" in result.stdout
    assert "autopilot-uav1" in result.stdout and "mission" in result.stdout


def test_status_with_nothing_running_says_so() -> None:
    from swarmbus.session import free_tcp_port

    result = run_cli(["status", "--connect", f"tcp/127.0.0.1:{free_tcp_port()}", "--timeout", "1"])
    assert result.returncode == 1
    assert "nothing is running" in result.stderr
