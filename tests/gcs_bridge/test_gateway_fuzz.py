"""10⁵ hostile MAVLink frames against the gateway while real autopilots fly.

Plume, lockstep physics and two real autopilots; uav1 holds at 10 m, uav2 stands disarmed on
the ground. A seeded fuzzer (tests/support/mavfuzz.py, seed printed) sends random bytes,
corrupted and truncated frames, valid commands for other systems / components / from impostors, and
well-formed frames with invalid fields for our vehicles, in batches: each batch ends with a
sentinel request and its replies are compared with what every frame must get. Afterwards: the
gateway is alive, the vehicles did nothing (seen on the bus), the parameters are unchanged, and
a normal client uploads a mission and takes off.

``PLUMESWARM_FUZZ_SEED`` / ``PLUMESWARM_FUZZ_FRAMES`` override the seed and the frame count.
"""

from __future__ import annotations

import collections
import math
import os
import socket
import time
from pathlib import Path

import pytest

from gcs_bridge.dialect import mavlink
from gcs_bridge.frames import enu_to_geodetic
from swarmbus.messages import FlightMode
from swarmbus.scenario import load_scenario
from tests.support.buswatch import BusWatch
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, mission_item, write_scenario
from tests.support.mavfuzz import Fuzzer, Reply, Target, reply_of
from tests.support.procs import wait_until, zenoh_network

SEED = int(os.environ.get("PLUMESWARM_FUZZ_SEED", "20261122"))
FRAMES = int(os.environ.get("PLUMESWARM_FUZZ_FRAMES", "100000"))
BATCH_DATAGRAMS = 48  # well inside the gateway's socket buffer: nothing is dropped
NAN = math.nan
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


def _result_name(kind: str, code: int) -> str:
    enum = "MAV_RESULT" if kind == "COMMAND_ACK" else "MAV_MISSION_RESULT"
    entry = mavlink.enums[enum].get(code)
    return (
        entry.name.removeprefix("MAV_RESULT_").removeprefix("MAV_MISSION_") if entry else str(code)
    )


def replies_until(
    client: MavClient, token: int, timeout_s: float, texts: collections.Counter[str]
) -> list[Reply]:
    """Every reply the client gets up to the sentinel's MESSAGE_INTERVAL ``token``; the
    STATUSTEXTs on the way are counted in ``texts``."""
    out: list[Reply] = []
    deadline = time.monotonic() + timeout_s
    while True:
        while client.inbox:
            m = client.inbox.popleft()
            if m.get_type() == "STATUSTEXT" and not m.chunk_seq:  # a long text's chunks: one
                texts[m.get_type()] += 1
            r = reply_of(m)
            if r is None:
                continue
            out.append(r)
            if r[0] == "MESSAGE_INTERVAL" and r[2] == token:
                return out
        if time.monotonic() > deadline:
            raise AssertionError(f"the gateway did not answer batch sentinel {token} in time")
        client.pump(0.05)


@pytest.mark.timeout(600)  # ~1 min on a quiet 2-core machine; 3 min at load average 20
def test_gateway_survives_100k_hostile_frames(tmp_path: Path) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", 2)
    sc = load_scenario(scenario)
    targets = []
    for vid, sysid, airborne in (("uav1", 1, True), ("uav2", 2, False)):
        spawn = next(v.spawn_enu_m for v in sc.vehicles if v.id == vid)
        lat, lon, _ = enu_to_geodetic(spawn, sc.world.origin)
        targets.append(Target(sysid, airborne, lat, lon))
    print(f"\nfuzz seed {SEED} (PLUMESWARM_FUZZ_SEED), {FRAMES} frames")
    junk = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    stranger = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    with (
        zenoh_network() as (net, router),
        vehicles(net, scenario, tmp_path, ["uav1", "uav2"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3", "api_links=off") as gw,
        MavClient(gcs_port) as gcs,
        MavClient(0) as client,
        junk,
        stranger,
    ):
        watch = BusWatch(router, ["uav1", "uav2"])
        for s in (1, 2):
            gcs.wait_standby(s)
            # and ticking: standby comes from the autopilots' statuses, which they publish
            # before the physics' first tick; an Arm before it is refused (no vehicle state yet)
            gcs.wait_type("GLOBAL_POSITION_INT", s)
        # uav1 takes off (MAVProxy's way: relative altitude, lat/lon 0) and holds at 10 m
        assert gcs.command(1, 22, 0, 0, 0, NAN, 0, 0, 10) == ACCEPTED
        assert gcs.command(1, 400, 1) == ACCEPTED
        wait_until(
            lambda: (s := watch.latest_status("uav1")) is not None and s.mode == FlightMode.HOLD,
            120.0,
            "uav1 holding after its takeoff",
        )
        params_before = {s: gcs.params(s) for s in (1, 2)}
        gw_addr = gcs.addr_of[1]
        status_before = {v: watch.latest_status(v) for v in ("uav1", "uav2")}
        fuzzer = Fuzzer(SEED, targets)
        datagrams = fuzzer.datagrams(FRAMES)
        socks = {"junk": junk, "stranger": stranger, "client": client.sock}
        watch.mark()
        gcs.drain()

        start = time.monotonic()
        replies = 0
        results: collections.Counter[tuple[str, int]] = collections.Counter()
        texts: collections.Counter[str] = collections.Counter()
        mismatches: list[str] = []
        for b, first in enumerate(range(0, len(datagrams), BATCH_DATAGRAMS)):
            batch = datagrams[first : first + BATCH_DATAGRAMS]
            expected: collections.Counter[Reply] = collections.Counter()
            for d in batch:
                socks[d.sender].sendto(d.data, gw_addr)
                expected.update(d.expect)
            token = 40000 + b
            data, sentinel_replies = fuzzer.sentinel(targets[b % 2], token)
            client.sock.sendto(data, gw_addr)
            expected.update(sentinel_replies)
            got = collections.Counter(replies_until(client, token, 30.0, texts))
            replies += sum(got.values())
            for (kind, _, a, b), n in got.items():
                if kind in ("COMMAND_ACK", "MISSION_ACK"):
                    results[(kind, b if kind == "COMMAND_ACK" else a)] += n
            if got != expected and len(mismatches) < 5:
                mismatches.append(
                    f"batch {b}: missing {dict(expected - got)}, unexpected {dict(got - expected)}"
                )
            assert gw.poll() is None, f"the gateway died in batch {b} (seed {SEED})"
        wall = time.monotonic() - start
        frames = sum(d.frames for d in datagrams)
        print(
            f"fuzz: {frames} frames in {len(datagrams)} datagrams "
            f"({collections.Counter(d.sender for d in datagrams)}), {replies} replies, "
            f"{wall:.1f} s, {frames / wall:.0f} frames/s"
        )
        print(f"fuzz: client frames per case: {fuzzer.counts}")
        print(
            "fuzz: ACK results: "
            + ", ".join(
                f"{kind} {_result_name(kind, code)} {n}"
                for (kind, code), n in sorted(results.items())
            )
        )
        assert not mismatches, f"seed {SEED}: wrong replies:\n" + "\n".join(mismatches)
        # refusals are explained in STATUSTEXTs, but a flood of them is rate-limited
        # (10 at once, then 5/s per vehicle and link): no amplification towards every GCS
        print(f"fuzz: {texts['STATUSTEXT']} STATUSTEXTs")
        assert texts["STATUSTEXT"] <= 2 * (10 + 5 * (wall + 1))
        assert frames >= FRAMES

        # the vehicles did nothing: uav1 held in the air, uav2 stayed disarmed, no mission
        # or parameter changed, and the fuzzed autopilots are still both there
        for vid in ("uav1", "uav2"):
            window = watch.status_window(vid)
            assert window, f"no status of {vid} during the fuzz"
            before = status_before[vid]
            assert before is not None
            assert {(s.mode, s.armed, s.mission_count) for s in window} == {
                (before.mode, before.armed, before.mission_count)
            }, f"{vid} changed during the fuzz"
        assert watch.spread_m("uav1") < 1.0
        assert watch.spread_m("uav2") < 0.05
        gcs.drain()
        assert {s: gcs.params(s) for s in (1, 2)} == params_before
        assert gw.poll() is None
        gateway_log = (tmp_path / "gateway.log").read_text(errors="replace")
        assert "Traceback" not in gateway_log, "a frame raised inside the gateway"

        # a normal ground station still works: mission upload and takeoff on uav2
        lat, lon = targets[1].lat, targets[1].lon
        items = [
            mission_item(2, 0, mavlink.MAV_CMD_NAV_TAKEOFF, lat, lon, 8),
            mission_item(2, 1, mavlink.MAV_CMD_NAV_WAYPOINT, lat + 5e-5, lon, 8),
            mission_item(2, 2, mavlink.MAV_CMD_NAV_LAND, lat + 5e-5, lon, 0),
        ]
        assert gcs.upload(2, items) == mavlink.MAV_MISSION_ACCEPTED
        wait_until(
            lambda: (s := watch.latest_status("uav2")) is not None and s.mission_count == 3,
            30.0,
            "uav2's new mission on the bus",
        )
        assert gcs.command(2, 22, 0, 0, 0, NAN, 0, 0, 6) == ACCEPTED
        assert gcs.command(2, 400, 1) == ACCEPTED
        wait_until(
            lambda: (
                (s := watch.latest_status("uav2")) is not None
                and s.armed
                and s.mode == FlightMode.TAKEOFF
            ),
            60.0,
            "uav2 taking off",
        )
        watch.close()
