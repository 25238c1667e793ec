"""examples/coop_plugin.py: a cooperative behaviour written outside plumeswarm goes through the
swarm table of ``bench gsl`` as docs/swarm.md says, and its members do talk."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import ClassVar

import msgspec

from agents.behavior import BehaviorContext
from agents.behaviors.seeking import SeekStep
from agents.peer_link import Received
from examples.coop_plugin import BestReading, SharedBest
from plumeswarm.gsl.episode import EpisodeSpec, kinematic_episode
from swarmbus.messages import Setpoint
from tests.support.procs import REPO

PLUGIN = "mine=examples.coop_plugin:SharedBest"


def test_the_example_goes_through_the_swarm_table(tmp_path: Path) -> None:
    args = ["--algorithms", PLUGIN, "--environments", "steady_gaussian", "--sensors", "ideal"]
    args += ["--runs", "1", "--seed", "1000", "--time-limit", "20", "--jobs", "1"]
    args += ["--vehicles", "1,3", "--out", str(tmp_path)]
    res = subprocess.run(
        [sys.executable, "-m", "plumeswarm", "bench", "gsl", *args],
        cwd=REPO,  # examples.coop_plugin is importable from the repository root
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    rows = json.loads((tmp_path / "gsl.json").read_text())
    assert [(r["algorithm"], r["vehicles"]) for r in rows if r["algorithm"] == "mine"] == [
        ("mine", 1),
        ("mine", 3),
    ]
    table = (tmp_path / "gsl.md").read_text().split("Swarm scaling", 1)[1]
    for n in (1, 3):
        assert f"| mine | steady_gaussian | ideal | {n} |" in table
    # the command docs/swarm.md gives is the one this test runs
    docs = (REPO / "docs" / "swarm.md").read_text()
    assert f"--algorithms {PLUGIN}" in docs and "--vehicles 1,3" in docs


class Listening(SharedBest):
    """SharedBest that keeps what each member heard, by receiver."""

    heard: ClassVar[dict[str, list[Received]]] = {}

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.vehicle_id = ctx.vehicle_id
        Listening.heard[self.vehicle_id] = []

    def seek(self, step: SeekStep) -> Setpoint | None:
        Listening.heard[self.vehicle_id].extend(step.inbox)
        return super().seek(step)


def test_the_members_share_their_best_readings() -> None:
    Listening.heard.clear()
    behavior = "tests.examples.test_coop_plugin:Listening"
    spec = EpisodeSpec("mine", "steady_gaussian", "ideal", run=0, seed=1000, time_limit_s=20.0,
                       behavior=behavior, vehicles=3)  # fmt: skip
    kinematic_episode(spec)
    heard = [r for got in Listening.heard.values() for r in got]
    assert heard and {type(r.message) for r in heard} == {BestReading}
    assert len({r.sender for r in heard}) >= 2  # more than one member found gas and said so
    # a member says its best only when it improves: what one hears from a peer only grows
    for receiver, got in Listening.heard.items():
        for sender in {r.sender for r in got}:
            values = [r.message.g_m3 for r in got if r.sender == sender]  # type: ignore[attr-defined]
            assert values == sorted(set(values)), (receiver, sender, values)
    # msgpack of an array of three float64: 1 + 3 x 9 bytes, as the example's docstring says
    assert {len(msgspec.msgpack.encode(r.message)) for r in heard} == {28}
