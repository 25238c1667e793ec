"""A scenario larger than MAVLink can address (systems 1–254): the gateway serves exactly the
vehicles that have a sysid, says once how many it leaves out, and only those sysids beat."""

from __future__ import annotations

import logging
import time

import msgspec
import pytest
import zenoh

from deploy.scaling import scale_scenario
from gcs_bridge.gateway import Gateway
from gcs_bridge.options import GatewayOptions
from swarmbus.keys import Keys
from swarmbus.scenario import load_scenario
from swarmbus.session import free_udp_block, open_session
from tests.support.mavclient import MavClient
from tests.support.procs import Network

N = 256
ALIVE = ["uav1", "uav254", "uav255", "uav256"]  # autopilots present: two on MAVLink, two not


def test_only_vehicles_with_a_sysid_are_served_and_beat(
    network: tuple[Network, zenoh.Session], caplog: pytest.LogCaptureFixture
) -> None:
    net, session = network
    base = scale_scenario(load_scenario(), N)
    gcs_port = free_udp_block(1)
    scenario = msgspec.structs.replace(
        base, gateway=msgspec.structs.replace(base.gateway, gcs_port=gcs_port)
    )
    keys = Keys(scenario.world.name)
    options = GatewayOptions(telemetry_hz=scenario.gateway.telemetry_hz, api_links=False)
    ids = [v.id for v in scenario.vehicles]
    tokens = [session.liveliness().declare_token(keys.node_health(f"autopilot-{v}")) for v in ALIVE]
    caplog.set_level(logging.INFO, logger="gcs_bridge")
    try:
        with (
            open_session(net.client) as gw_session,
            Gateway(scenario, options, ids, gw_session, keys) as gw,
            MavClient(gcs_port) as client,
        ):
            assert sorted(gw.by_sysid) == list(range(1, 255))
            assert set(gw.vehicles) == set(ids) - {"uav255", "uav256"}
            notes = [r.getMessage() for r in caplog.records if "not on MAVLink" in r.getMessage()]
            assert len(notes) == 1, notes
            assert notes[0].startswith("2 vehicle(s) not on MAVLink")
            assert "1–254" in notes[0]

            def beats(sysid: int) -> int:
                return len(client.logged("HEARTBEAT", sysid))

            deadline = time.monotonic() + 60.0
            while beats(1) < 3 or beats(254) < 3:
                assert time.monotonic() < deadline, (
                    f"heartbeats: 1 → {beats(1)}, 254 → {beats(254)}"
                )
                gw.poll(0.05)
                client.pump(0.0)
            sources = {m.get_srcSystem() for m in client.log if m.get_type() == "HEARTBEAT"}
            assert sources == {1, 254}  # uav2…uav253 have no autopilot; 255, 256 no sysid
    finally:
        for t in tokens:
            t.undeclare()
