"""Partitions between hosts in realtime mode: ``sim`` (router, physics, plume, and a driver that
took the three vehicles off to 8 m) and ``agents`` (the autopilots) in their own namespaces, as in
``test_netns_partition``; the agents' veth is set down in ``sim`` and up again while the vehicles
hold in the air. The world cannot wait: after the tick's deadline the physics holds each
vehicle 5 s, then lands it itself (its failsafe: level, 0.7 m/s down), each autopilot lands too
once it has had no
tick for ``failsafe.state_loss_timeout_s``, both sides log what was late, and after the healing
the autopilots command their vehicles again, in LAND, down to the ground. No vehicle crashes.
Needs root. Measured numbers: docs/reliability.md, "Realtime mode: the vehicles follow their
failsafe"."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import psutil
import pytest

from swarmbus.keys import process_node
from tests.support.procs import REPO, wait_until
from tests.support.scale import THREE, Shape, patience, process_of
from tests.system.test_netns_deploy import ROUTER, Hosts, _ip, three_namespaces
from tests.system.test_netns_partition import seed_scenario, sim_and_agents

pytestmark = pytest.mark.netns
VEHICLES = ("uav1", "uav2", "uav3")
ALTITUDE_M = 8.0
CONTROL_DT_S = 1.0 / 120.0
DRIVER = "tests.support.rt_flight"
# the physics' failsafe (failsafe.hold_s = 5 s by default: PX4's COM_FAIL_ACT_T)
HOLD_THEN_LAND = r"the physics holds it 5 s, then lands it \(its failsafe\)"


def _driver(h: Hosts, tmp: Path, out: Path, vehicles: Sequence[str] = VEHICLES) -> Path:
    """The driver of ``vehicles`` in ``sim``, stopped with the hosts (first); the file it
    touches when every vehicle holds at 8 m."""
    ready = tmp / "airborne"
    args = [ROUTER, ",".join(vehicles), str(ALTITUDE_M), str(ready), str(out)]
    with open(tmp / "driver.console", "wb") as console:
        proc = subprocess.Popen(
            ["ip", "netns", "exec", h.ns["sim"], sys.executable, "-m", DRIVER, *args],
            cwd=REPO,
            env=h.env(),
            stdout=console,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    h.procs["driver"] = proc  # `ip netns exec` execs: the pid is the driver's
    h.family.append(psutil.Process(proc.pid))
    return ready


def _landed(out: Path, vehicles: Sequence[str] = VEHICLES) -> bool:
    last = _last_lines(out)
    return len(last) == len(vehicles) and all(
        v["on_ground"] and not v["armed"] for v in last.values()
    )


def _last_lines(out: Path) -> dict[str, dict[str, Any]]:
    last: dict[str, dict[str, Any]] = {}
    if out.exists():
        for line in out.read_text().splitlines():
            if line.strip():
                row = json.loads(line)
                last[row["id"]] = row
    return last


REALTIME = ('mode = "lockstep"', 'mode = "realtime"')


def partition(
    tmp: Path, seconds: float, change: tuple[str, str] = REALTIME, shape: Shape = THREE
) -> tuple[dict[str, str], list[dict[str, Any]]]:
    """The logs (physics, and each vehicle's autopilot process's by vehicle) and the flight
    records of a run (realtime, or the seed scenario with ``change``; ``shape``'s vehicles and
    their grouping) whose agents host is cut off for ``seconds`` while the vehicles hold at
    8 m."""
    vehicles, per_process = shape
    slow = patience(vehicles)
    scenario = seed_scenario(tmp, *change, vehicles=len(vehicles))
    with three_namespaces() as ns:
        h = sim_and_agents(ns, tmp, scenario, per_process)
        physics = tmp / "sim" / "physics.log"
        out = tmp / "flight.jsonl"
        try:
            h.up("sim")
            h.up("agents")
            wait_until(
                lambda: "handshake done" in physics.read_text(), 60.0 * slow, "the first tick"
            )
            ready = _driver(h, tmp, out, vehicles)
            wait_until(ready.exists, 180.0 * slow, "every vehicle holding at 8 m")
            time.sleep(1.0)
            _ip("-n", ns["sim"], "link", "set", "vageh", "down")
            time.sleep(seconds)
            _ip("-n", ns["sim"], "link", "set", "vageh", "up")
            wait_until(
                lambda: all(f"{v} commanded again" in physics.read_text() for v in vehicles),
                90.0 * slow,
                "every autopilot to command its vehicle again",
            )
            wait_until(
                lambda: _landed(out, vehicles), 90.0 * slow, "every vehicle landed and disarmed"
            )
        finally:
            h.stop()  # the driver first
        logs = {"physics": physics.read_text()}
        for vid, group in process_of(vehicles, per_process).items():
            name = process_node("autopilot", group)
            logs[vid] = (tmp / "agents" / f"{name}.log").read_text()
        rows = [json.loads(line) for line in out.read_text().splitlines() if line.strip()]
        return logs, rows


def check(
    logs: dict[str, str], rows: list[dict[str, Any]], seconds: float, landing_seen: bool
) -> None:
    physics = logs["physics"]
    print(re.findall(r".*(?:no command from|commanded again|without a command).*", physics))
    for vid in VEHICLES:
        # the physics' side: its failsafe took the vehicle while airborne, then gave it back
        assert re.search(rf"no command from {vid}: {HOLD_THEN_LAND}", physics)
        back = re.findall(rf"{vid} commanded again after (\d+) ticks without", physics)
        assert back, vid
        # the autopilot's side: no tick for its timeout (1 s), it landed, then ticks came back
        text = logs[vid]
        print(re.findall(r".*(?:vehicle state lost|ticks again).*", text))
        assert re.search(rf"{vid}: no tick for [0-9.]+ s after tick \d+: vehicle state lost", text)
        # nothing reaches it while the link is down: its silence outlasts the partition
        silent = [float(s) for s in re.findall(r"ticks again after ([0-9.]+) s without", text)]
        assert silent and max(silent) >= seconds, (vid, silent)
        own = [r for r in rows if r["id"] == vid]
        assert not any(r["crashed"] for r in own), f"{vid} crashed"
        # after the healing its status says why (LAND while it flies it down), then it landed
        lost = [r for r in own if r["failsafe"].startswith("vehicle state lost")]
        assert lost, vid
        if landing_seen:
            assert any(r["mode"] == "land" for r in lost), vid
        assert own[-1]["on_ground"] and not own[-1]["armed"] and not own[-1]["crashed"]
    # the run's summary counts the ticks; at least the partition less the tick's 2 s deadline
    summary = re.search(
        r"ticks without a command \(physics failsafe: hold, then land\): (.*)", physics
    )
    assert summary, "no summary"
    for vid, n, sim_s in re.findall(r"(uav\d): (\d+) ticks \(([0-9.]+) s sim\)", summary[1]):
        assert int(n) * CONTROL_DT_S == pytest.approx(float(sim_s), abs=0.01)
        assert float(sim_s) >= seconds - 2.0, (vid, sim_s)


def test_realtime_partition_of_5_s_the_physics_then_the_autopilots_land_the_vehicles(
    tmp_path: Path,
) -> None:
    """8 m at 0.7 m/s is more than 5 s: the autopilots, back, fly the rest in LAND."""
    logs, rows = partition(tmp_path, 5.0)
    check(logs, rows, 5.0, landing_seen=True)


def test_realtime_partition_of_60_s_the_physics_lands_the_vehicles_and_the_autopilots_disarm(
    tmp_path: Path,
) -> None:
    """The physics holds them 5 s, then lands them within 13 s; the autopilots, back, find them
    down and disarm."""
    logs, rows = partition(tmp_path, 60.0)
    check(logs, rows, 60.0, landing_seen=False)
    for vid in VEHICLES:
        assert re.search(rf"tick \d+: {vid} commanded again after", logs["physics"]), vid
