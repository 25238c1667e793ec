"""Hosts agree on the scenario: an autopilot started with a modified copy of the physics's
scenario file is refused at the lockstep handshake (both processes log one line naming both
hashes, the autopilot exits non-zero); one started with a copy of equal content (another
path, a comment) takes part."""

from __future__ import annotations

import re
from pathlib import Path

from swarmbus.codec import decode
from swarmbus.messages import SimTick
from tests.support.mavclient import write_scenario
from tests.support.procs import NodeProcs, keys_for, wait_until, zenoh_network

HASH = "[0-9a-f]{16}"


def test_another_scenario_is_refused_equal_content_joins(tmp_path: Path) -> None:
    here, _, _ = write_scenario(tmp_path / "scenario.toml", 1)
    text = here.read_text()
    (tmp_path / "other").mkdir()
    (tmp_path / "same").mkdir()
    modified = tmp_path / "other" / "scenario.toml"
    modified.write_text(text.replace("x = 30.0", "x = 31.0", 1))  # uav1's second waypoint
    same = tmp_path / "same" / "scenario.toml"
    same.write_text("# the same scenario on another host\n" + text)
    logs = tmp_path
    with (
        zenoh_network() as (net, router),
        NodeProcs(net, here, logs) as procs,
        NodeProcs(net, modified, logs) as other,
        NodeProcs(net, same, logs) as copy,
    ):
        ticks: list[int] = []
        sub = router.declare_subscriber(
            keys_for().tick(), lambda s: ticks.append(decode(s.payload.to_bytes(), SimTick).tick)
        )
        procs.start("physics")
        refused = other.start("autopilot", "--vehicle", "uav1", name="refused")
        assert refused.wait(60) == 2
        line = re.search(
            rf"refused by physics: scenario hash ({HASH}) here, ({HASH}) at physics",
            (logs / "refused.log").read_text(),
        )
        assert line is not None, (logs / "refused.log").read_text()[-2000:]
        theirs, ours = line.groups()
        assert theirs != ours
        physics_log = logs / "physics.log"
        wait_until(lambda: "refusing autopilot-uav1" in physics_log.read_text(), 10.0, "refusal")
        assert f"scenario hash {theirs} there, {ours} here" in physics_log.read_text()
        assert not ticks  # the physics waits for uav1's autopilot
        joined = copy.start("autopilot", "--vehicle", "uav1", name="joined")
        wait_until(lambda: len(ticks) > 100, 60.0, "100 ticks with the joined autopilot")
        sub.undeclare()
        assert joined.poll() is None
        assert "refused by" not in (logs / "joined.log").read_text()
