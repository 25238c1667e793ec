"""The same filament scenario in a meandering wind, run twice in lockstep by a real physics
process against one real plume process: the same tick stream, bit for bit — states (the wind
acts on them through drag) and the shared sensor query's plume values. The second run asks
the plume for times it has already passed, as after a physics restart."""

from __future__ import annotations

from pathlib import Path

from swarmbus.codec import decode
from swarmbus.messages import SimTick
from swarmbus.session import Presence
from tests import test_physics_node
from tests.procs import NodeProcs

setup = test_physics_node.setup  # the same fixture: physics network, procs and tick watch
Watch = test_physics_node.Watch

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


def test_a_filament_scenario_twice_in_lockstep_gives_the_same_ticks_and_plume_values(
    setup: tuple[NodeProcs, Watch], tmp_path: Path
) -> None:
    procs, watch = setup
    sc = test_physics_node.write_scenario(tmp_path, extra_time=DYNAMIC)
    procs.start("plume", "--scenario", str(sc), name="plume")
    presence = Presence(watch.session, test_physics_node.KEYS)
    assert presence.wait_for(lambda alive: "plume" in alive, 60.0), sorted(presence.alive)
    presence.close()
    ticks = 480
    first = test_physics_node.stream_hash(procs, watch, sc, ticks, "run1")
    seen = [decode(watch.raw[k], SimTick) for k in range(ticks + 1)]
    values = [v for t in seen if t.plume_values for v in t.plume_values.values_g_m3 or []]
    assert sum(t.plume_queried for t in seen) >= ticks // 3
    assert max(values) > 0.0, "the filaments never reached the vehicles"
    second = test_physics_node.stream_hash(procs, watch, sc, ticks, "run2")
    assert first == second
