"""Partitions between hosts (lockstep): ``sim`` (router, physics, plume) and ``agents`` (the three
autopilots, vehicles on the ground) in their own network namespaces, as in
``test_netns_deploy``; the agents' veth is set down in ``sim`` (``ip link set down``) and up
again. With ``time.unreachable_grace_s = 10``: a 5 s partition holds the clock (no tick is
stepped without every vehicle's command, so the state stream is the one of a run without it)
and the run goes on when the link is back; a 60 s partition holds it 10 s, then drops the
vehicles (the tick named), and after the healing they answer again and rejoin. A 5 s partition
while the vehicles fly their missions (started on a known tick, as in ``test_faults_resume``)
leaves every state and reading bit for bit those of the same flight without it. The 5 s ones
also with 32 vehicles in 4 autopilot processes of 8 (marker ``scale``). Needs root."""

from __future__ import annotations

import re
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import msgspec
import psutil
import pytest

from deploy.scaling import scale_scenario, write_scenario
from swarmbus.scenario import parse_scenario
from tests.support.flown import Flown, load
from tests.support.hosts import write_hosts as write_hosts_file
from tests.support.procs import REPO, wait_until
from tests.support.scale import SHAPES, THREE, Shape, patience
from tests.system.test_faults_resume import START_TICK, assert_nothing_lost, mission_scenario
from tests.system.test_netns_deploy import ADDRESSES, ROUTER, Hosts, _ip, three_namespaces

pytestmark = pytest.mark.netns
GRACE_S = 10.0


def seed_scenario(tmp: Path, old: str, new: str, vehicles: int = 3) -> Path:
    """The seed scenario with ``old`` replaced by ``new`` (once), in ``tmp``; with more
    ``vehicles`` than its three, scaled by ``deploy.scaling`` (as ``demo --vehicles``), its
    start-up timeout lengthened by :func:`patience`."""
    base = (REPO / "swarmbus" / "scenarios" / "novak2018.toml").read_text()
    assert old in base, old
    scenario = tmp / "scenario.toml"
    text = base.replace(old, new, 1)
    sc = parse_scenario(text, str(scenario))
    if vehicles == len(sc.vehicles):
        scenario.write_text(text)
        return scenario
    sc = scale_scenario(sc, vehicles)
    slow = patience([v.id for v in sc.vehicles])
    start = msgspec.structs.replace(sc.time, startup_timeout_s=sc.time.startup_timeout_s * slow)
    return write_scenario(msgspec.structs.replace(sc, time=start), scenario)


def sim_and_agents(
    ns: dict[str, str],
    tmp: Path,
    scenario: Path,
    per_process: int = 1,
    served: Sequence[str] | None = None,
) -> Hosts:
    """``sim`` (router, physics, plume) and ``agents`` (the autopilots, ``per_process``
    vehicles each, of ``served`` or every vehicle) flying ``scenario``."""
    roles = {"sim": ["router", "physics", "plume"], "agents": ["autopilot"]}
    vehicles = {"agents": list(served)} if served is not None else None
    hosts = write_hosts_file(tmp / "hosts.toml", ROUTER, roles, ADDRESSES, vehicles=vehicles)
    first, rest = hosts.read_text().split("\n", 1)
    hosts.write_text(f'{first}\nscenario = "{scenario}"\n{rest}')
    more = ("--vehicles-per-process", str(per_process)) if per_process > 1 else ()
    return Hosts(ns, hosts, tmp, up_args=more)


def partition(tmp: Path, seconds: float, shape: Shape = THREE) -> str:
    """The physics log of a run whose agents host is cut off for ``seconds``."""
    vehicles, per_process = shape
    slow = patience(vehicles)
    grace = ("[time]\n", f"[time]\nunreachable_grace_s = {GRACE_S}\n")
    scenario = seed_scenario(tmp, *grace, vehicles=len(vehicles))
    with three_namespaces() as ns:
        h = sim_and_agents(ns, tmp, scenario, per_process)
        log = tmp / "sim" / "physics.log"
        try:
            h.up("sim")
            h.up("agents")
            wait_until(lambda: "handshake done" in log.read_text(), 60.0 * slow, "the first tick")
            time.sleep(2.0)
            _ip("-n", ns["sim"], "link", "set", "vageh", "down")
            time.sleep(seconds)
            _ip("-n", ns["sim"], "link", "set", "vageh", "up")
            wait_until(
                lambda: "the run goes on" in (t := log.read_text()) or "back in the lockstep" in t,
                90.0 * slow,
                "the agents to answer again",
            )
            time.sleep(3.0)
        finally:
            h.stop(first=["sim"])  # the physics' log ends with the run: nobody stops before it
        return log.read_text()


@pytest.mark.parametrize("shape", SHAPES)
def test_partition_of_5_s_holds_the_clock(shape: Shape, tmp_path: Path) -> None:
    text = partition(tmp_path, 5.0, shape)
    print(text[-3000:])
    # the vehicles whose answer to the tick had not left before the cut
    assert re.search(r"no answer from uav\d.*holding the clock up to 10\.0 s", text)
    answered = [float(s) for s in re.findall(r"every participant answered after ([0-9.]+) s", text)]
    assert answered and max(answered) > 2.0, answered  # the 2 s timeout plus the wait
    assert " dropped " not in text.replace(" dropped 0", ""), "a vehicle was dropped"
    # the physics' own count at its stop: no tick stepped without every vehicle's command (its
    # failsafe never flew one), so the stream is the one of a run without the partition
    assert "every vehicle commanded on every tick" in text


def test_partition_of_60_s_drops_after_the_grace_and_rejoins(tmp_path: Path) -> None:
    text = partition(tmp_path, 60.0)
    print(text[-3000:])
    assert "holding the clock up to 10.0 s" in text
    dropped = re.findall(r"tick \d+: dropped (uav\d(?:, uav\d)*) after", text)
    assert dropped, "no vehicle was dropped after the grace"
    for vid in {v for line in dropped for v in line.split(", ")}:
        assert re.search(rf"{vid} answered tick \d+: back in the lockstep", text), vid


def in_sim(h: Hosts, name: str, module: str, *args: str) -> subprocess.Popen[bytes]:
    """``python -m MODULE ARGS`` in ``sim``, stopped with the hosts (first)."""
    with open(h.out / f"{name}.console", "wb") as console:
        proc = subprocess.Popen(
            ["ip", "netns", "exec", h.ns["sim"], sys.executable, "-m", module, *args],
            cwd=REPO, env=h.env(), stdout=console, stderr=subprocess.STDOUT,
            start_new_session=True,
        )  # fmt: skip
    h.procs[name] = proc  # `ip netns exec` execs: the pid is the module's
    h.family.append(psutil.Process(proc.pid))
    return proc


def missions(tmp: Path, shape: Shape, cut_s: float) -> tuple[Flown, int, str]:
    """What the flight of ``shape``'s missions (the test scenario of ``test_faults_resume``:
    in a row, started on tick START_TICK, a scripted gate in ``sim`` the last vehicle) kept,
    uav1's last tick seen on its first leg, and the physics log; with ``cut_s`` > 0 the agents
    are cut off that long from then on."""
    vehicles, per_process = shape
    slow = patience(vehicles)
    tmp.mkdir()
    grace = f"unreachable_grace_s = {GRACE_S}\n"
    path = mission_scenario(tmp / "scenario.toml", vehicles, grace)
    gate = f"uav{len(vehicles) + 1}"
    release = tmp / "release"
    with three_namespaces() as ns:
        h = sim_and_agents(ns, tmp, path, per_process, vehicles)
        try:
            h.up("sim")
            h.up("agents")
            in_sim(h, "gate", "tests.support.scripted_participant", "--connect", ROUTER,
                   "--scenario", str(path), "--vehicle", gate, "--throttle", "0",
                   "--delay-tick", str(START_TICK), "--delay-s", str(300 * slow),
                   "--release-file", str(release))  # fmt: skip
            flier = in_sim(h, "flight", "tests.support.lockstep_flight", ROUTER, str(path),
                           str(START_TICK), str(release), str(tmp))  # fmt: skip
            on_leg = tmp / "on_leg"
            wait_until(
                lambda: on_leg.exists() or flier.poll() is not None, 300 * slow, "uav1's leg"
            )
            if cut_s > 0:
                _ip("-n", ns["sim"], "link", "set", "vageh", "down")
                time.sleep(cut_s)
                _ip("-n", ns["sim"], "link", "set", "vageh", "up")
            assert flier.wait(300 * slow) == 0, (tmp / "flight.console").read_text()[-3000:]
        finally:
            h.stop(first=["sim"])  # the physics' log ends with the run: nobody stops before it
        log = (tmp / "sim" / "physics.log").read_text()
        return load(tmp / "flown.msgpack"), int(on_leg.read_text()), log


@pytest.mark.parametrize("shape", SHAPES)
def test_partition_of_5_s_in_flight_every_state_and_reading_is_that_of_a_run_without_it(
    shape: Shape, tmp_path: Path
) -> None:
    cut, cut_at, text = missions(tmp_path / "cut", shape, 5.0)
    whole, _, whole_text = missions(tmp_path / "whole", shape, 0.0)
    held = re.search(r"tick (\d+): no answer from uav\d.*holding the clock up to 10\.0 s", text)
    print(held[0] if held else None, re.findall(r".*every participant answered after.*", text))
    assert held, "the partition held no tick"
    assert " dropped " not in text.replace(" dropped 0", ""), "a vehicle was dropped"
    assert "every vehicle commanded on every tick" in text
    assert "no answer from" not in whole_text
    # the cut came while uav1 flew its first leg, and everything after it is the run without it
    assert int(held[1]) > cut_at, (held[1], cut_at)
    assert_nothing_lost(cut, whole, cut_at)
