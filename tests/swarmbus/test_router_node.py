"""Two real processes meet on a real Zenoh network through the router role."""

from __future__ import annotations

import zenoh

from swarmbus.session import NetworkConfig, Presence, free_tcp_port, open_session
from tests.support.procs import Network, NodeProcs, keys_for


def test_router_node_carries_liveliness_between_peers() -> None:
    net = Network(free_tcp_port())
    with NodeProcs(net) as procs:
        procs.start("router", "--listen", net.endpoint, name="router")
        client = NetworkConfig(connect=[net.endpoint], listen=["tcp/127.0.0.1:0"])
        with open_session(client) as session:
            presence = Presence(session, keys_for())
            assert presence.wait_for(lambda alive: "router" in alive, 20.0), (
                f"router token never seen; alive={sorted(presence.alive)}"
            )
            presence.close()
        assert isinstance(session, zenoh.Session)
