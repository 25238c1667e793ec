"""The journal of ``plumeswarm bench gsl`` keeps each episode's behaviour parameters: a grid
resumed after a behaviour's class attribute changed flies that behaviour's episodes again,
and says so; a line kept before the check is reused, and that is said too."""

from __future__ import annotations

import csv
import json
import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pytest

from plumeswarm.gsl.grid import behavior_digest
from plumeswarm.gsl.registry import behavior_parameters, tuned_behavior
from tests.plumeswarm.test_gsl_protocol import OUTSIDE
from tests.support.procs import REPO

# A behaviour the test can change: two vehicles fly upwind and declare where they are after
# ``declare_after_s`` (5 s), then hold there.
GUARDED = OUTSIDE

GRID = [
    "bench", "gsl", "--algorithms", "mine=guarded_behavior:Upwind",
    "--environments", "steady_gaussian", "--sensors", "ideal", "--runs", "2",
    "--time-limit", "10", "--jobs", "1",
]  # fmt: skip
EPISODES = 6  # random_walk, mine, oracle × 2 runs
TABLES = ("runs.csv", "gsl.json", "gsl.md", "paired.json")
RAN = re.compile(r"^grid: (\d+) episodes, (\d+) already done, (\d+) to run$", re.M)


def _bench(module_dir: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """The grid, with ``guarded_behavior`` importable from ``module_dir`` (no bytecode kept:
    every run reads the file as it is)."""
    env = dict(
        os.environ,
        PYTHONPATH=f"{REPO}{os.pathsep}{module_dir}",
        PYTHONDONTWRITEBYTECODE="1",
    )
    result = subprocess.run(
        [sys.executable, "-m", "plumeswarm", *GRID, *extra, "--out", str(out)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    return result


def _ran(result: subprocess.CompletedProcess[str]) -> tuple[int, ...]:
    match = RAN.search(result.stdout)
    assert match is not None, result.stdout[-1000:]
    return tuple(int(g) for g in match.groups())


def _notices(result: subprocess.CompletedProcess[str]) -> list[str]:
    """The stderr lines about the journal (the progress bar left out)."""
    return [line for line in result.stderr.splitlines() if "episode(s)" in line]


def _lines(journal: Path) -> list[dict[str, object]]:
    """The journal's episode lines (its first line is the grid's header)."""
    return [json.loads(line) for line in journal.read_text().splitlines()[1:]]


def _declared_s(out: Path) -> list[float]:
    """When ``mine`` declared, run by run, from runs.csv."""
    with (out / "runs.csv").open() as f:
        return [float(r["declared_s"]) for r in csv.DictReader(f) if r["algorithm"] == "mine"]


def _tables(out: Path) -> dict[str, bytes]:
    return {name: (out / name).read_bytes() for name in TABLES}


def test_a_changed_class_attribute_flies_its_episodes_again(tmp_path: Path) -> None:
    module = tmp_path / "guarded_behavior.py"
    module.write_text(GUARDED)
    out = tmp_path / "grid"
    journal = out / "episodes.jsonl"

    assert _ran(_bench(tmp_path, out)) == (EPISODES, 0, EPISODES)
    first = _lines(journal)
    assert len(first) == EPISODES and all(isinstance(r["behavior"], str) for r in first)
    for t in _declared_s(out):  # 5 s after its first step, to within one 0.05 s tick
        assert t == pytest.approx(5.0, abs=0.051)

    # the same behaviour: nothing flown, nothing said
    same = _bench(tmp_path, out)
    assert _ran(same) == (EPISODES, EPISODES, 0)
    assert _notices(same) == []
    assert len(_lines(journal)) == EPISODES

    # one class attribute changed: mine's 2 episodes flown again, the floor and ceiling kept
    assert "    declare_after_s = 5.0\n" in GUARDED
    module.write_text(GUARDED.replace("declare_after_s = 5.0", "declare_after_s = 2.25"))
    changed = _bench(tmp_path, out)
    assert _ran(changed) == (EPISODES, EPISODES - 2, 2)
    assert _notices(changed) == [
        f"2 episode(s) in {journal} flown again: the parameters of their behaviour changed (mine)"
    ]
    lines = _lines(journal)
    assert len(lines) == EPISODES + 2
    assert {r["episode"] for r in lines[EPISODES:]} == {
        "mine/steady_gaussian/ideal run 0",
        "mine/steady_gaussian/ideal run 1",
    }
    assert lines[EPISODES]["behavior"] != first[0]["behavior"]
    for t in _declared_s(out):
        assert t == pytest.approx(2.25, abs=0.051)

    # resumed again: nothing to fly, and the tables of a grid flown at once with the change
    assert _ran(_bench(tmp_path, out)) == (EPISODES, EPISODES, 0)
    fresh = tmp_path / "fresh"
    _bench(tmp_path, fresh)
    assert _tables(out) == _tables(fresh)


def test_a_line_kept_without_the_digest_is_reused_and_said(tmp_path: Path) -> None:
    (tmp_path / "guarded_behavior.py").write_text(GUARDED)
    out = tmp_path / "grid"
    journal = out / "episodes.jsonl"
    _bench(tmp_path, out)
    tables = _tables(out)
    header, *rest = journal.read_text().splitlines()
    old = [{k: v for k, v in json.loads(line).items() if k != "behavior"} for line in rest]
    journal.write_text("\n".join([header, *(json.dumps(r, sort_keys=True) for r in old)]) + "\n")

    resumed = _bench(tmp_path, out)
    assert _ran(resumed) == (EPISODES, EPISODES, 0)
    assert _notices(resumed) == [
        f"{EPISODES} episode(s) reused from {journal} without a check of their behaviour's "
        "parameters (kept before the check existed); to fly them again give another --out or "
        "delete that file"
    ]
    assert _tables(out) == tables


def test_shards_merged_keep_each_episodes_digest(tmp_path: Path) -> None:
    (tmp_path / "guarded_behavior.py").write_text(GUARDED)
    shards = [tmp_path / "s1", tmp_path / "s2"]
    for i, out in enumerate(shards, 1):
        _bench(tmp_path, out, "--shard", f"{i}/2")
    kept = {r["key"]: r["behavior"] for out in shards for r in _lines(out / "episodes.jsonl")}
    assert len(kept) == EPISODES and len(set(kept.values())) == 3  # one per algorithm
    merged = tmp_path / "merged"
    env = dict(os.environ, PYTHONPATH=f"{REPO}{os.pathsep}{tmp_path}")
    merge = ["bench", "gsl", "merge", *map(str, shards), "--out", str(merged)]
    subprocess.run(
        [sys.executable, "-m", "plumeswarm", *merge],
        cwd=REPO,
        env=env,
        capture_output=True,
        check=True,
        timeout=300,
    )
    assert {r["key"]: r["behavior"] for r in _lines(merged / "episodes.jsonl")} == kept


@dataclass(frozen=True)
class Statistics:
    distances_m: tuple[float, ...]
    names: frozenset[str]


class Base:
    own_state: ClassVar[tuple[str, ...]] = ("heading",)
    speed_m_s = 2.0
    turn_rad = 0.5
    _cache: ClassVar[dict[str, float]] = {}

    def step(self) -> None: ...


class Child(Base):
    speed_m_s = 3.0
    statistics = Statistics((30.0, 50.0), frozenset({"a", "b", "c"}))

    @property
    def speed(self) -> float:
        return self.speed_m_s

    @classmethod
    def build(cls) -> Child:
        return cls()

    @staticmethod
    def helper() -> None: ...


CHILD = f"{__name__}:Child"


def test_the_parameters_are_the_public_class_attributes_nearest_first() -> None:
    assert behavior_parameters(CHILD) == {
        "speed_m_s": 3.0,
        "statistics": Statistics((30.0, 50.0), frozenset({"a", "b", "c"})),
        "turn_rad": 0.5,
    }


def test_the_digest_is_the_same_in_every_process_and_follows_the_parameters() -> None:
    code = f"from plumeswarm.gsl.grid import behavior_digest; print(behavior_digest({CHILD!r}))"
    digests = {
        subprocess.run(
            [sys.executable, "-c", code],
            cwd=REPO,
            env=dict(os.environ, PYTHONPATH=str(REPO), PYTHONHASHSEED=seed),
            capture_output=True,
            text=True,
            check=True,
            timeout=120,
        ).stdout.strip()
        for seed in ("1", "2")
    }
    assert digests == {behavior_digest(CHILD)}
    walk = "agents.behaviors.random_walk:RandomWalk"
    assert behavior_digest(tuned_behavior(walk, {"speed_m_s": 1.0})) != behavior_digest(walk)
    assert behavior_digest(tuned_behavior(walk, {"speed_m_s": 2.0})) == behavior_digest(walk)
