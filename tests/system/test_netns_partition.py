"""Partitions between hosts (lockstep): ``sim`` (router, physics, plume) and ``agents`` (the three
autopilots, vehicles on the ground) in their own network namespaces, as in
``test_netns_deploy``; the agents' veth is set down in ``sim`` (``ip link set down``) and up
again. With ``time.unreachable_grace_s = 10``: a 5 s partition holds the clock (no tick is
stepped without every vehicle's command, so the state stream is the one of a run without it)
and the run goes on when the link is back; a 60 s partition holds it 10 s, then drops the
vehicles (the tick named), and after the healing they answer again and rejoin. Needs root."""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from tests.support.procs import REPO, wait_until
from tests.system.test_netns_deploy import Hosts, _ip, three_namespaces, write_hosts

pytestmark = pytest.mark.netns
GRACE_S = 10.0


def seed_scenario(tmp: Path, old: str, new: str) -> Path:
    """The seed scenario with ``old`` replaced by ``new`` (once), in ``tmp``."""
    base = (REPO / "swarmbus" / "scenarios" / "novak2018.toml").read_text()
    scenario = tmp / "scenario.toml"
    scenario.write_text(base.replace(old, new, 1))
    return scenario


def sim_and_agents(ns: dict[str, str], tmp: Path, scenario: Path) -> Hosts:
    """``sim`` (router, physics, plume) and ``agents`` (the autopilots) flying ``scenario``."""
    hosts = write_hosts(
        tmp / "hosts.toml", {"sim": ["router", "physics", "plume"], "agents": ["autopilot"]}
    )
    first, rest = hosts.read_text().split("\n", 1)
    hosts.write_text(f'{first}\nscenario = "{scenario}"\n{rest}')
    return Hosts(ns, hosts, tmp)


def partition(tmp: Path, seconds: float) -> str:
    """The physics log of a run whose agents host is cut off for ``seconds``."""
    scenario = seed_scenario(tmp, "[time]\n", f"[time]\nunreachable_grace_s = {GRACE_S}\n")
    with three_namespaces() as ns:
        h = sim_and_agents(ns, tmp, scenario)
        log = tmp / "sim" / "physics.log"
        try:
            h.up("sim")
            h.up("agents")
            wait_until(lambda: "handshake done" in log.read_text(), 60.0, "the first tick")
            time.sleep(2.0)
            _ip("-n", ns["sim"], "link", "set", "vageh", "down")
            time.sleep(seconds)
            _ip("-n", ns["sim"], "link", "set", "vageh", "up")
            wait_until(
                lambda: "the run goes on" in (t := log.read_text()) or "back in the lockstep" in t,
                90.0,
                "the agents to answer again",
            )
            time.sleep(3.0)
        finally:
            h.stop()
        return log.read_text()


def test_partition_of_5_s_holds_the_clock(tmp_path: Path) -> None:
    text = partition(tmp_path, 5.0)
    print(text[-3000:])
    # the vehicles whose answer to the tick had not left before the cut
    assert re.search(r"no answer from uav\d.*holding the clock up to 10\.0 s", text)
    answered = [float(s) for s in re.findall(r"every participant answered after ([0-9.]+) s", text)]
    assert answered and max(answered) > 2.0, answered  # the 2 s timeout plus the wait
    assert " dropped " not in text.replace(" dropped 0", ""), "a vehicle was dropped"


def test_partition_of_60_s_drops_after_the_grace_and_rejoins(tmp_path: Path) -> None:
    text = partition(tmp_path, 60.0)
    print(text[-3000:])
    assert "holding the clock up to 10.0 s" in text
    dropped = re.findall(r"tick \d+: dropped (uav\d(?:, uav\d)*) after", text)
    assert dropped, "no vehicle was dropped after the grace"
    for vid in {v for line in dropped for v in line.split(", ")}:
        assert re.search(rf"{vid} answered tick \d+: back in the lockstep", text), vid
