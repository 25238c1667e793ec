"""A 60 s partition in lockstep with the vehicles in the air: ``sim`` (router, physics, plume,
and a driver that took the three vehicles off to 8 m) and ``agents`` (the autopilots) in their
own network namespaces, the agents' veth set down in ``sim`` for 60 s. The clock holds for the
grace (10 s here), then the physics drops the autopilots and flies their vehicles under its
failsafe: it holds them 5 s (PX4's ``COM_FAIL_ACT_T``), then lands them at 0.7 m/s. After the
healing each autopilot finds that ticks were stepped without it, lands (its vehicle is already
down) and disarms. No vehicle crashes. The same with the seed scenario scaled to 32 vehicles in
4 autopilot processes of 8 (marker ``scale``). Needs root."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from tests.support.scale import SHAPES, Shape
from tests.system.test_netns_partition import GRACE_S
from tests.system.test_netns_partition_realtime import HOLD_THEN_LAND, partition

pytestmark = pytest.mark.netns
ALTITUDE_M = 8.0


@pytest.mark.parametrize("shape", SHAPES)
def test_lockstep_partition_of_60_s_with_the_vehicles_at_8_m_no_vehicle_crashes(
    shape: Shape, tmp_path: Path
) -> None:
    change = ("[time]\n", f"[time]\nunreachable_grace_s = {GRACE_S}\n")
    logs, rows = partition(tmp_path, 60.0, change, shape)
    physics = logs["physics"]
    print(re.findall(r".*(?:dropped|no command from|commanded again|without a command).*", physics))
    assert re.search(r"tick \d+: dropped uav\d", physics), "nobody was dropped after the grace"
    for vid in shape[0]:
        assert re.search(rf"no command from {vid}: {HOLD_THEN_LAND}", physics), vid
        assert re.search(rf"tick \d+: {vid} commanded again after \d+ ticks", physics), vid
        text = logs[vid]
        print(re.findall(r".*stepped without this autopilot.*", text))
        assert re.search(r"ticks \([0-9.]+ s sim\) were stepped without this autopilot", text)
        own = [r for r in rows if r["id"] == vid]
        assert own, vid
        assert not any(r["crashed"] for r in own), f"{vid} crashed"
        # it held at 8 m before the cut, and no state shows a fall: the descent is the failsafe's
        # (0.7 m/s) and the autopilot's landing, never faster than 1.5 m/s downwards
        airborne = [r for r in own if not r["on_ground"]]
        assert max(r["z"] for r in airborne) > ALTITUDE_M - 0.5, vid
        assert min(r["v"][2] for r in airborne) > -1.5, (vid, min(r["v"][2] for r in airborne))
        assert own[-1]["on_ground"] and not own[-1]["armed"], own[-1]
