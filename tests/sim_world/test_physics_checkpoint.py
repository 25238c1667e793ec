"""Physics checkpoints: a world restored from a checkpoint file continues exactly like the world
that never stopped (the check that the saved state is complete), and the file's guards."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sim_world import checkpoint
from sim_world.checkpoint import CheckpointError, ProgressMarker
from sim_world.world import World
from swarmbus.messages import VehicleState
from swarmbus.scenario import Scenario, parse_scenario
from tests.support.physics_rig import vehicles_toml

CONTROL_HZ = 120
SUBSTEPS = 2


def scenario(world: str = "default", second_type: str = "iris", extra: str = "") -> Scenario:
    vehicles = vehicles_toml(
        ("ground", "iris", (0.0, 0.0, 0.0)),
        ("air", second_type, (5.0, 0.0, 20.0)),
        ("lifting", "iris", (-5.0, 3.0, 0.0)),
    )
    text = f"""{extra}
[world]
name = "{world}"
[time]
physics_hz = {CONTROL_HZ * SUBSTEPS}
control_hz = {CONTROL_HZ}
{vehicles}"""
    return parse_scenario(text)


def commands(tick: int) -> dict[str, list[float]]:
    """A fixed, tick-dependent script: idle on the ground, wobbling in the air, a lift-off."""
    wobble = [0.6 + 0.05 * math.sin(0.07 * tick + i) for i in range(4)]
    lift = 0.85 if 20 <= tick < 90 else 0.6
    return {
        "ground": [0.1, 0.1, 0.1, 0.1],
        "air": wobble,
        "lifting": [lift, lift * 1.01, lift, lift * 0.99],
    }


def run(world: World, first: int, last: int) -> list[list[VehicleState]]:
    """Ticks first..last-1 as the physics node does them; the states after each."""
    out = []
    for tick in range(first, last):
        for vid, cmd in commands(tick).items():
            world.set_motors_enabled(vid, tick % 50 != 7 or vid != "lifting")  # a dropped tick
            world.apply(vid, cmd)
        world.step(SUBSTEPS)
        out.append(world.states(tick + 1))
    return out


def test_restored_world_continues_bit_for_bit(tmp_path: Path) -> None:
    sc = scenario()
    path = tmp_path / "physics.ckpt"
    with World(sc) as original:
        run(original, 0, 30)  # lifting is leaving the ground
        checkpoint.save(path, original.checkpoint(tick=30))
        expected = run(original, 30, 300)
        rotors = {v: original.rotor_speeds(v) for v in original.vehicle_ids}
    with World(sc) as resumed:
        cp = checkpoint.load(path)
        resumed.restore(cp)
        assert (cp.tick, resumed.step_count) == (30, 30 * SUBSTEPS)
        got = run(resumed, 30, 300)
        assert {v: resumed.rotor_speeds(v) for v in resumed.vehicle_ids} == rotors
    assert got == expected  # every field of every state of every tick, exactly
    with World(sc) as untouched:  # and taking a checkpoint changed nothing in the original
        assert run(untouched, 0, 300)[30:] == expected
    # the span covers resting contact, a lift-off, a touch-down and free flight
    by_vid = {
        v: [next(s for s in t if s.vehicle_id == v) for t in expected]
        for v in ("ground", "lifting", "air")
    }
    assert all(s.on_ground and not s.crashed for s in by_vid["ground"])
    lifting = [s.on_ground for s in by_vid["lifting"]]
    assert False in lifting and lifting[-1], "in the air, then touched down"
    assert not any(s.on_ground for s in by_vid["air"])


@pytest.mark.parametrize(
    ("model", "turbulence"),
    [("meander", ""), ("field", ""), ("meander", "\n[wind.turbulence]\nshare = 0.5\n")],
    ids=["meander", "field", "meander+turbulence"],
)
def test_restored_world_in_a_time_varying_wind_continues_bit_for_bit(
    tmp_path: Path, model: str, turbulence: str
) -> None:
    """The wind is a function of the sim time (and position): a world resumed at tick 30 sees
    the same wind as the one that ran through, so the same states, bit for bit."""
    wind = f'[wind]\nmodel = "{model}"\n[wind.meander]\npreset = "large"\n{turbulence}'
    sc = scenario(extra=wind)
    path = tmp_path / "physics.ckpt"
    with World(sc) as original:
        run(original, 0, 30)
        checkpoint.save(path, original.checkpoint(tick=30))
        expected = run(original, 30, 240)
    with World(sc) as resumed:
        resumed.restore(checkpoint.load(path))
        assert run(resumed, 30, 240) == expected
    with World(scenario()) as steady:  # the wind did act on the flying vehicle
        run(steady, 0, 30)
        air = [next(s for s in t if s.vehicle_id == "air") for t in run(steady, 30, 240)]
    meandered = [next(s for s in t if s.vehicle_id == "air") for t in expected]
    assert air[-1].position_enu_m != meandered[-1].position_enu_m


def test_a_fresh_world_is_not_the_resumed_one() -> None:
    """The comparison above can fail: without the restore the worlds differ."""
    sc = scenario()
    with World(sc) as original, World(sc) as fresh:
        run(original, 0, 60)
        assert run(original, 60, 80) != run(fresh, 60, 80)


def test_checkpoint_of_another_world_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "physics.ckpt"
    with World(scenario()) as world:
        checkpoint.save(path, world.checkpoint(tick=0))
    cp = checkpoint.load(path)
    for other in (scenario(world="elsewhere"), scenario(second_type="typhoon_h480")):
        with World(other) as world, pytest.raises(CheckpointError, match="the checkpoint is of"):
            world.restore(cp)


@pytest.mark.parametrize("content", [b"", b"\x00garbage", b"\x81\xa6format\xa3old"])
def test_unreadable_checkpoint_file_is_a_clear_error(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "physics.ckpt"
    path.write_bytes(content)
    with pytest.raises(CheckpointError, match=r"physics\.ckpt"):
        checkpoint.load(path)
    with pytest.raises(CheckpointError, match="cannot read"):
        checkpoint.load(tmp_path / "missing.ckpt")


def test_save_replaces_atomically_and_leaves_no_temporary(tmp_path: Path) -> None:
    path = tmp_path / "physics.ckpt"
    with World(scenario()) as world:
        checkpoint.save(path, world.checkpoint(tick=0))
        run(world, 0, 12)
        checkpoint.save(path, world.checkpoint(tick=12))
    assert checkpoint.load(path).tick == 12
    assert [p.name for p in tmp_path.iterdir()] == ["physics.ckpt"]


def test_progress_marker_survives_its_writer(tmp_path: Path) -> None:
    path = tmp_path / "physics.ckpt.progress"
    assert ProgressMarker.read(path) is None
    with ProgressMarker(path) as marker:
        marker.mark(41)
        marker.mark(42)
        noted = ProgressMarker.read(path)  # another process reads the file while it runs
    assert noted is not None and noted[0] == 42
    with ProgressMarker(path) as again:  # reopened by the next process: still there
        assert ProgressMarker.read(path) == noted
        again.mark(7)
    assert ProgressMarker.read(path) is not None
    checkpoint.remove(tmp_path / "physics.ckpt")
    assert not path.exists()


def test_progress_marker_in_a_missing_directory_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="cannot write"):
        ProgressMarker(tmp_path / "missing" / "physics.ckpt.progress")
