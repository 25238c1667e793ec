"""MAVSDK (4.x, its bundled C++ core) flies three vehicles through the gateway.

Discover all three, set the takeoff altitude (a parameter), arm, take off, upload a 4-waypoint
mission to each, start them, see every MISSION_ITEM_REACHED and the progress reach the end,
read the concentration (NAMED_VALUE_FLOAT via MavlinkDirect), land, see them disarm.
Runs against the real plume + physics + autopilot stack.
"""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path
from typing import Any

import pytest

from gcs_bridge.frames import enu_to_geodetic
from swarmbus.scenario import Origin
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import first, write_scenario
from tests.support.procs import zenoh_network

mavsdk = pytest.importorskip("mavsdk")

from mavsdk.asyncio import ComponentType, Configuration, Mavsdk  # noqa: E402
from mavsdk.asyncio.plugins.action import ActionAsync  # noqa: E402
from mavsdk.asyncio.plugins.mavlink_direct import MavlinkDirectAsync  # noqa: E402
from mavsdk.asyncio.plugins.mission_raw import MissionItem, MissionRawAsync  # noqa: E402
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync  # noqa: E402

ORIGIN = Origin()
N = 3
ALT_M = 8.0


def spawn_y(i: int) -> float:  # tests.support.mavclient.scenario_text's row of vehicles
    return 4.0 * i - 2.0 * (N - 1)


def mission(i: int) -> list[Any]:
    y = spawn_y(i)
    points = [(20.0, y), (27.0, y), (27.0, y + 3.0), (22.0, y + 3.0)]
    items = []
    for seq, (e, n) in enumerate(points):
        lat, lon, _ = enu_to_geodetic((e, n, 0.0), ORIGIN)
        items.append(
            MissionItem(
                seq,
                6,
                16,
                1 if seq == 0 else 0,
                1,
                0.0,
                1.0,
                0.0,
                math.nan,
                round(lat * 1e7),
                round(lon * 1e7),
                ALT_M,
                0,
            )
        )
    return items


async def fly(system: Any, sysid: int) -> dict[str, Any]:
    tel, act, raw, direct = (
        TelemetryAsync(system),
        ActionAsync(system),
        MissionRawAsync(system),
        MavlinkDirectAsync(system),
    )
    reached: list[int] = []
    readings: list[float] = []

    async def listen(name: str, sink: list[Any], field: str) -> None:
        async for msg in direct.subscribe_message(name):
            if msg.system_id == sysid:
                sink.append(json.loads(msg.fields_json)[field])

    listeners = [
        asyncio.create_task(listen("MISSION_ITEM_REACHED", reached, "seq")),
        asyncio.create_task(listen("NAMED_VALUE_FLOAT", readings, "value")),
    ]
    try:
        await first(
            tel.subscribe_health(),
            lambda h: h.is_global_position_ok and h.is_home_position_ok and h.is_armable,
            f"{sysid} ready to arm",
        )
        await act.set_takeoff_altitude(ALT_M)
        assert await act.get_takeoff_altitude() == pytest.approx(ALT_M)
        await act.arm()
        await act.takeoff()
        await first(tel.subscribe_in_air(), bool, f"{sysid} in the air")
        await first(
            tel.subscribe_position(),
            lambda p: p.relative_altitude_m > ALT_M - 0.5,
            f"{sysid} at {ALT_M} m",
        )
        await raw.upload_mission(mission(sysid - 1))
        downloaded = await raw.download_mission()
        assert [(d.x, d.y) for d in downloaded] == [(m.x, m.y) for m in mission(sysid - 1)]
        await raw.start_mission()
        await first(
            raw.subscribe_mission_progress(),
            lambda p: p.total == 4 and p.current == 4,
            f"{sysid} mission complete",
        )
        await act.land()
        await first(tel.subscribe_armed(), lambda armed: not armed, f"{sysid} disarmed", 180.0)
        return {"reached": list(reached), "readings": len(readings)}
    finally:
        for t in listeners:
            t.cancel()


async def discover_and_fly(port: int) -> dict[int, dict[str, Any]]:
    config = Configuration.create_with_component_type(ComponentType.GROUND_STATION)
    async with Mavsdk(config) as sdk:
        await sdk.add_any_connection(f"udpin://127.0.0.1:{port}")

        async def all_three() -> dict[int, Any]:
            while True:
                found = {
                    await s.get_system_id(): s
                    for s in await sdk.get_systems()
                    if await s.has_autopilot()
                }
                if len(found) >= N:
                    return found
                await asyncio.sleep(0.2)

        systems = await asyncio.wait_for(all_three(), 120.0)
        assert sorted(systems) == [1, 2, 3]
        results = await asyncio.gather(*(fly(systems[i], i) for i in sorted(systems)))
        return dict(zip(sorted(systems), results, strict=True))


def test_mavsdk_flies_three_vehicles(tmp_path: Path) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", N)
    ids = [f"uav{i + 1}" for i in range(N)]
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ids, backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
    ):
        results = asyncio.run(discover_and_fly(gcs_port))
    for sysid, r in results.items():
        assert r["reached"] == [0, 1, 2, 3], f"sysid {sysid}: MISSION_ITEM_REACHED {r['reached']}"
        assert r["readings"] > 0, f"sysid {sysid}: no conc_gm3 NAMED_VALUE_FLOAT"
