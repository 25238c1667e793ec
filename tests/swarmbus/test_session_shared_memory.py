"""``network.shared_memory``: Zenoh's shared-memory transport on or off, and messages above the
shared-memory threshold (3 KB) delivered either way between two real sessions."""

from __future__ import annotations

import json
import threading

import pytest

from swarmbus.scenario import parse_scenario, resolve_scenario_path
from swarmbus.session import NetworkConfig, free_tcp_port, open_session, zenoh_config


def test_the_option_reaches_zenohs_configuration() -> None:
    assert zenoh_config(NetworkConfig()).get_json("transport/shared_memory/enabled") == "true"
    off = NetworkConfig(shared_memory=False)
    assert zenoh_config(off).get_json("transport/shared_memory/enabled") == "false"


def test_a_scenario_sets_it_under_network() -> None:
    text = resolve_scenario_path("novak2018").read_text()
    assert parse_scenario(text).network.shared_memory is True
    # a table header before the first [[vehicles]] keeps the file's other tables intact
    off = text.replace("[[vehicles]]", "[network]\nshared_memory = false\n\n[[vehicles]]", 1)
    assert parse_scenario(off).network.shared_memory is False


@pytest.mark.parametrize("shared_memory", [True, False])
def test_a_large_message_arrives_whole(shared_memory: bool) -> None:
    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    a = NetworkConfig(connect=[], listen=[endpoint], shared_memory=shared_memory)
    b = NetworkConfig(connect=[endpoint], listen=[], shared_memory=shared_memory)
    payload = bytes(range(256)) * 64  # 16 KB: above the 3 KB shared-memory threshold
    got: list[bytes] = []
    arrived = threading.Event()

    def on_sample(sample: object) -> None:
        got.append(bytes(sample.payload.to_bytes()))  # type: ignore[attr-defined]
        arrived.set()

    with open_session(a) as pub_side, open_session(b) as sub_side:
        sub = sub_side.declare_subscriber("test/shm", on_sample)
        pub = pub_side.declare_publisher("test/shm")
        for _ in range(50):  # until the subscription has propagated
            pub.put(payload)
            if arrived.wait(0.1):
                break
        sub.undeclare()
        pub.undeclare()
    assert arrived.is_set(), json.dumps({"shared_memory": shared_memory})
    assert got[0] == payload
