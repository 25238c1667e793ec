"""The same filament scenario in a meandering wind, run twice in lockstep by a real physics
process against one real plume process: the same tick stream, bit for bit — states (the wind
acts on them through drag) and the shared sensor query's plume values. The second run asks
the plume for times it has already passed, as after a physics restart."""

from __future__ import annotations

from pathlib import Path

from swarmbus.codec import decode
from swarmbus.messages import SimTick
from tests.support.physics_rig import (
    Watch,
    fly_scripted,
    stream_hash,
    two_vehicle_scenario,
    wait_for_plume,
)
from tests.support.procs import NodeProcs, wait_until

DYNAMIC = """
[wind]
speed_m_s = 2.0
model = "meander"
[wind.meander]
preset = "large"
[plume]
model = "filament"
[[plume.sources]]
x_m = -3.0
y_m = 0.0
release_rate_g_s = 10.0
release_height_m = 2.0
[plume.filament]
release_rate_hz = 100.0
centerline_diffusivity_m2_s = 0.05
growth_m2_s = 0.05
[sensor]
period_ticks = 3
"""


def _start_plume(procs: NodeProcs, watch: Watch, sc: Path) -> None:
    procs.start("plume", "--scenario", str(sc), name="plume")
    wait_for_plume(watch)


def test_a_filament_scenario_twice_in_lockstep_gives_the_same_ticks_and_plume_values(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, extra_time=DYNAMIC)
    _start_plume(procs, watch, sc)
    ticks = 480
    first = stream_hash(procs, watch, sc, ticks, "run1")
    seen = [decode(watch.raw[k], SimTick) for k in range(ticks + 1)]
    values = [v for t in seen if t.plume_values for v in t.plume_values.values_g_m3 or []]
    assert sum(t.plume_queried for t in seen) >= ticks // 3
    assert max(values) > 0.0, "the filaments never reached the vehicles"
    second = stream_hash(procs, watch, sc, ticks, "run2")
    assert first == second


def _run(
    procs: NodeProcs, watch: Watch, sc: Path, label: str, last: int, *physics_args: str
) -> dict[int, bytes]:
    """Physics (with ``physics_args``) and a scripted participant until tick ``last``; the raw
    SimTicks the test's session saw, by tick."""
    fly_scripted(procs, watch, sc, last, label, physics_args=physics_args)
    wait_until(lambda: watch.last_tick >= last, 10.0, f"tick {last} at the subscriber")
    with watch.lock:
        return dict(watch.raw)


def test_a_physics_stopped_and_resumed_from_its_checkpoint_sees_the_same_plume_and_wind(
    rig: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    """An uninterrupted run to tick 480 against a run stopped at tick 250 and resumed from its
    checkpoint (tick 240) to 480: from the restored tick on, every SimTick is the same bytes —
    states under the meandering wind's drag and the filaments' values at the vehicles."""
    procs, watch = rig
    sc = two_vehicle_scenario(tmp_path, extra_time=DYNAMIC)
    _start_plume(procs, watch, sc)
    straight = _run(procs, watch, sc, "straight", 480)
    ckpt = tmp_path / "physics.ckpt"
    options = ("--set", f"checkpoint={ckpt}", "--set", "checkpoint_period_s=1.0")
    _run(procs, watch, sc, "before", 250, *options)
    resumed = _run(procs, watch, sc, "after", 480, *options)
    first = min(resumed)
    assert first == 240, sorted(resumed)[:5]  # the checkpoint of 2 s (120 Hz), not the spawn
    for k in range(first + 1, 481):
        assert resumed[k] == straight[k], k
    values = [decode(straight[k], SimTick).plume_values for k in range(first + 1, 481)]
    assert any(v is not None and max(v.values_g_m3 or [0.0]) > 0.0 for v in values)
