"""A flood of garbage on the bus keys the gateway reads is logged in a few lines, not one line a
message (docs/reliability.md, "Bounds": refusals are rate-limited per key, 5 s), and the
gateway goes on serving the vehicle.

The fake autopilots stand uav1 and uav2 by; the test puts 300 undecodable payloads on each of
``vehicle/uav1/status`` and ``sim/tick`` in about a second, then reads the gateway's log: each
kind is named at once (the first refusal), the rest are counted for the next line, so within
a 5 s period the log holds one line per kind, where one line per message would be 600. A
reading is decoded only when telemetry asks for it (the newest replaces an older one unread):
its refusal is checked on the gateway's ``Vehicle`` itself.
"""

from __future__ import annotations

import logging
import re
import time
from pathlib import Path

import pytest
import zenoh

from gcs_bridge.vehicle import Vehicle
from swarmbus.keys import Keys
from swarmbus.scenario import load_scenario
from swarmbus.session import open_session
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, write_scenario
from tests.support.procs import wait_until, zenoh_network

FLOOD = 300  # garbage payloads a key
GARBAGE = b"\xc1\xff not msgpack \x00"
KINDS = ("status of uav1", "a tick on")  # how the gateway's lines name the two keys


def _refusals(log: Path) -> list[str]:
    return [ln for ln in log.read_text(errors="replace").splitlines() if "ignoring" in ln]


def test_a_flood_of_garbage_is_logged_once_a_kind_and_the_gateway_serves_on(
    tmp_path: Path,
) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", 2)
    keys = Keys()
    log = tmp_path / "gateway.log"
    block = zenoh.CongestionControl.BLOCK  # every put reaches the gateway: none dropped on the way
    with (
        zenoh_network() as (net, _router),
        open_session(net.client) as session,
        vehicles(net, scenario, tmp_path, ["uav1", "uav2"], speed=3.0),
        gateway(net, scenario, tmp_path) as gw,
        MavClient(gcs_port) as gcs,
    ):
        for sysid in (1, 2):
            gcs.wait_standby(sysid, 60.0)
        targets = (keys.vehicle_status("uav1"), keys.tick())
        t0 = time.monotonic()
        for _ in range(FLOOD):
            for key in targets:
                session.put(key, GARBAGE, congestion_control=block)
        flood_s = time.monotonic() - t0
        wait_until(
            lambda: all(any(k in ln for ln in _refusals(log)) for k in KINDS),
            20.0,
            "the gateway's refusal of each kind",
        )
        # still serving: uav1's heartbeats keep coming after the flood
        gcs.drain()
        gcs.wait_standby(1, 30.0)
        assert gw.poll() is None, "the gateway died"
        lines = _refusals(log)
    elapsed_s = time.monotonic() - t0
    print(f"{len(targets) * FLOOD} garbage payloads in {flood_s:.2f} s: {len(lines)} log lines")
    for line in lines:
        print("  " + line[:160])
    # one line at once per kind, and at most one more per 5 s with the count of the rest
    periods = 1 + int(elapsed_s / 5.0)
    for kind in KINDS:
        said = [ln for ln in lines if kind in ln]
        assert 1 <= len(said) <= periods, (kind, len(said), periods)
    counted = [int(m.group(1)) for ln in lines if (m := re.search(r"\((\d+) more refused", ln))]
    assert len(lines) <= len(KINDS) * periods and all(n > 0 for n in counted), lines


def test_a_vehicle_s_undecodable_readings_are_one_line_and_the_last_good_one_stays(
    caplog: pytest.LogCaptureFixture,
) -> None:
    v = Vehicle(load_scenario(), "uav1", 0, (0.0, 0.0, 0.0))
    with caplog.at_level(logging.WARNING, logger="gcs_bridge.vehicle"):
        for _ in range(FLOOD):
            v.feed_reading(GARBAGE)
            assert v.reading is None
    said = [r.getMessage() for r in caplog.records if "ignoring" in r.getMessage()]
    assert len(said) == 1 and "ConcentrationReading of uav1" in said[0], said
