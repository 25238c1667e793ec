"""When the physics saves its world and how it resumes (docs/physics.md, "Checkpoints and
restart"), with a real world and real files, driven tick by tick as the physics loop does."""

from __future__ import annotations

import logging
import re
import sys
from pathlib import Path

import pytest

from sim_world import checkpoint
from sim_world.checkpoint import ProgressMarker
from sim_world.checkpointer import Checkpointer
from sim_world.world import World
from swarmbus.messages import PlumeSample
from tests.sim_world.test_physics_checkpoint import CONTROL_HZ, SUBSTEPS, scenario

PERIOD_S = 0.5  # 60 ticks at 120 Hz
SENSOR_VALUES = PlumeSample(tick=108, values_g_m3=[0.5, 0.0, 1.25])


def fly(cps: Checkpointer, world: World, first: int, last: int) -> None:
    """Ticks first+1..last as the loop does them: step, save when due, mark as published."""
    for tick in range(first + 1, last + 1):
        world.step(SUBSTEPS)
        if tick >= cps.next_tick:
            cps.save(world, tick, SENSOR_VALUES if tick == 120 else None)
        cps.mark(tick)


def saves_logged(caplog: pytest.LogCaptureFixture) -> int:
    found = [r.getMessage() for r in caplog.records if "checkpoints: capture" in r.getMessage()]
    assert len(found) == 1, found
    return int(found[0].split()[0])


def test_the_world_is_saved_at_the_first_tick_and_every_period(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "physics.ckpt"
    caplog.set_level(logging.INFO, logger="sim_world.checkpointer")
    with World(scenario()) as world:
        cps = Checkpointer(path, PERIOD_S, CONTROL_HZ)
        assert cps.resume(world) is None  # no file: from the spawn
        cps.start(world, 0, None)
        fly(cps, world, 0, 150)
        cps.finish()
        cps.close()
    assert saves_logged(caplog) == 3  # ticks 0, 60 and 120
    saved = checkpoint.load(path)
    assert (saved.tick, saved.step_count) == (120, 120 * SUBSTEPS)
    assert saved.sim_time_s == 1.0
    assert saved.plume_sample == SENSOR_VALUES  # what tick 120 carries
    assert ProgressMarker.read(checkpoint.marker_path(path)) is not None


def test_a_resumed_run_says_what_it_replays_and_saves_one_period_later(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "physics.ckpt"
    with World(scenario()) as world:
        first = Checkpointer(path, PERIOD_S, CONTROL_HZ)
        first.start(world, 0, None)
        fly(first, world, 0, 130)  # killed after publishing tick 130
        first.finish()
        first.close()
    caplog.set_level(logging.INFO, logger="sim_world.checkpointer")
    with World(scenario()) as world:
        cps = Checkpointer(path, PERIOD_S, CONTROL_HZ)
        cp = cps.resume(world)
        assert cp is not None and cp.tick == 120 and world.step_count == 120 * SUBSTEPS
        assert cps.note == (
            "resumed from checkpoint at tick 120 (sim t=1.000 s), replayed 0.083 s (ticks 120..130)"
        )
        cps.start(world, 120, cp.plume_sample)
        fly(cps, world, 120, 179)
        cps.finish()
        cps.started()
        cps.close()
    assert saves_logged(caplog) == 0  # tick 120 is on disk already; tick 180 is next
    assert re.fullmatch(r".*, ticks stopped for \d+\.\d\d s wall", cps.note)


@pytest.mark.parametrize("path_given, period_s", [(False, PERIOD_S), (True, 0.0)])
def test_no_path_or_a_zero_period_saves_nothing(
    tmp_path: Path, path_given: bool, period_s: float
) -> None:
    path = tmp_path / "physics.ckpt"
    with World(scenario()) as world:
        cps = Checkpointer(path if path_given else None, period_s, CONTROL_HZ)
        assert cps.resume(world) is None
        cps.start(world, 0, None)
        assert cps.next_tick == sys.maxsize
        cps.finish()
        cps.close()
    assert list(tmp_path.iterdir()) == []
