"""Sixteen vehicles: every sysid appears, and telemetry arrives at the configured rates per
second of simulated time (the simulation runs faster than real time), SET_MESSAGE_INTERVAL
included. Rates are measured from the messages' own sim timestamps, never from wall time."""

from __future__ import annotations

from functools import partial
from pathlib import Path

from gcs_bridge.dialect import mavlink
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import (
    FAST_STREAMS,
    SLOW_STREAMS_HZ,
    MavClient,
    heard_all,
    measure_rates,
    write_scenario,
)
from tests.support.procs import zenoh_network

N = 16
HZ = 4.0


def test_sixteen_vehicles_telemetry_rates(tmp_path: Path) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", N, telemetry_hz=HZ)
    ids = [f"uav{i + 1}" for i in range(N)]
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ids, speed=2.0),
        gateway(net, scenario, tmp_path, "api_links=off", "cmd_timeout_s=3"),
        MavClient(gcs_port) as c,
    ):
        sysids: set[int] = set()
        c.wait(
            "all 16 sysids",
            partial(heard_all, sysids, N),
            120.0,
        )
        assert sysids == set(range(1, N + 1))
        assert c.command(N, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 30, 1e6 / 10.0) == 0
        assert c.command(N - 1, mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, 74, -1) == 0
        rates, wall = measure_rates(c, sorted(sysids), sim_seconds=8.0, timeout_s=180.0)
    streams = (*FAST_STREAMS, *SLOW_STREAMS_HZ)
    lines = [f"{'sysid':>5} " + " ".join(f"{k[:10]:>10}" for k in streams)]
    for s in sorted(rates):
        lines.append(f"{s:>5} " + " ".join(f"{rates[s].get(k, 0.0):>10.2f}" for k in streams))
    (tmp_path / "rates.txt").write_text("\n".join(lines) + f"\nwall {wall:.1f} s\n")
    print("\n".join(lines))
    for s, r in rates.items():
        for kind in FAST_STREAMS:
            if (s, kind) == (N, "ATTITUDE"):
                assert r[kind] >= 0.9 * 10.0, f"sysid {s} ATTITUDE at {r[kind]:.2f}/s, asked 10"
            elif (s, kind) == (N - 1, "VFR_HUD"):
                assert r.get(kind, 0.0) == 0.0, "VFR_HUD was turned off"
            else:
                assert r.get(kind, 0.0) >= 0.85 * HZ, f"sysid {s} {kind} at {r.get(kind)}/s"
        for kind, hz in SLOW_STREAMS_HZ.items():
            assert r.get(kind, 0.0) >= 0.7 * hz, f"sysid {s} {kind} at {r.get(kind)}/s"
