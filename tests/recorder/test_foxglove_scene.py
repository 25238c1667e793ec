"""The conversion of bus messages to Foxglove messages (no processes): rates in simulation time,
anchored timestamps, poses, colours, the plume, and every message decoding against the schema
the foxglove SDK declares."""

from __future__ import annotations

import itertools
import json
import math
import time
from collections import Counter
from pathlib import Path
from typing import Any

import foxglove
import numpy as np
import pytest
from mcap.reader import make_reader

from plume_service.from_scenario import field_from_scenario
from plume_service.service import StatePublisher
from recorder.foxglove.channels import (
    PLUME_STATE_MAX_SPHERES,
    PLUME_STATE_MIN_DIAMETER_M,
    PLUME_STATE_TOPIC,
    PLUME_TOPIC,
    TF_TOPIC,
    TRAILS_TOPIC,
    VEHICLES_TOPIC,
    Out,
    channel_schema,
    concentration_topic,
    encode,
    location_topic,
)
from recorder.foxglove.export import export_foxglove
from recorder.foxglove.layout import layout_json
from recorder.foxglove.live import LiveChannels, convert
from recorder.foxglove.scene import (
    FoxgloveScene,
)
from recorder.reader import ExportError
from recorder.sink import McapSink
from swarmbus import codec
from swarmbus.keys import Keys
from swarmbus.messages import (
    ConcentrationReading,
    PlumeMesh,
    PlumeState,
    SimTick,
    VehicleState,
)
from swarmbus.scenario import load_scenario, resolve_scenario_path
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from swarmbus.view_feed import Feed, MeshFetcher
from tests.support.foxglove_decode import ChannelDecoder, topic_messages
from tests.support.messages_samples import reading as noiseless_reading
from tests.support.messages_samples import vehicle_state
from tests.support.procs import REPO

CONTROL_HZ = 120
WALL0_NS = 1_800_000_000_123_456_789
NORTH_XYZW = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))  # nose (x) turned to north


def state(vid: str, k: int, x: float, xyzw: tuple[float, float, float, float]) -> VehicleState:
    return vehicle_state(
        vid, k, (x, 2.0, 10.0), control_hz=CONTROL_HZ, velocity_enu_m_s=(1.0, 0.0, 0.0),
        attitude_xyzw=xyzw, lat_deg=47.5, lon_deg=8.5, alt_m=510.0,
    )  # fmt: skip


def reading(vid: str, t: float, value: float | None) -> ConcentrationReading:
    return noiseless_reading(vid, t, (1.0, 2.0, 10.0), value)


_decoder = ChannelDecoder()


def decoded(o: Out) -> Any:
    """``o``'s message as Foxglove reads it: encoded, then decoded by its channel's schema."""
    cs = channel_schema(type(o.message))
    return _decoder.decode(cs.name, cs.encoding, cs.data, encode(o.message))


def fly(
    scene: FoxgloveScene,
    seconds: float,
    ids: list[str],
    sim0_s: float = 0.0,
    reading_lag_ticks: int = 2,
) -> list[Out]:
    """Feed ``seconds`` of ticks (all states, then each state alone, as the bus carries them)
    and a reading per vehicle every 12 ticks (10 Hz), ``reading_lag_ticks`` late (the plume
    answers in wall time: seconds of sim time in a fast lockstep); received at wall time = sim
    time."""
    out: list[Out] = []
    k0 = round(sim0_s * CONTROL_HZ)
    for k in range(k0, k0 + round(seconds * CONTROL_HZ)):
        t = k / CONTROL_HZ
        wall = WALL0_NS + round(t * 1e9) + 7_000  # some transport delay
        states = [
            state(v, k, 0.1 * k + i, NORTH_XYZW if i else (0.0, 0.0, 0.0, 1.0))
            for i, v in enumerate(ids)
        ]
        msgs: list[object] = [
            SimTick(tick=k, sim_time_s=t, control_dt_s=1 / CONTROL_HZ, states=states),
            *states,
        ]
        if k % 12 == 1 and k >= reading_lag_ticks:
            t_read = (k - reading_lag_ticks) / CONTROL_HZ
            msgs += [reading(v, t_read, 0.01 * (i + 1)) for i, v in enumerate(ids)]
        for m in msgs:
            out += scene.feed(m, wall)
    return out


def test_rates_are_counted_in_simulation_time_and_stamps_are_anchored_sim_time() -> None:
    sc = load_scenario(resolve_scenario_path(None))
    ids = [v.id for v in sc.vehicles]
    scene = FoxgloveScene(sc)
    lag = 3 * CONTROL_HZ  # readings 3 s of sim time late
    out = fly(scene, 4.0, ids, reading_lag_ticks=lag)
    per_topic = Counter(o.topic for o in out)
    # 4 s of simulation: /tf at 20 Hz, locations at 5 Hz, series at the sensor's 10 Hz,
    # trails at 0.5 Hz; the bodies once.
    assert per_topic[TF_TOPIC] == 80
    assert per_topic[TRAILS_TOPIC] == 1  # at 2 s (at 0 s no trail has two points yet)
    assert per_topic[VEHICLES_TOPIC] == 1
    for v in ids:
        assert per_topic[location_topic(v)] == 20
        # one per reading: ticks 1, 13, … below 480 that are at least ``lag``
        assert per_topic[concentration_topic(v)] == len(range(1, 480, 12)) - lag // 12
    anchor = WALL0_NS + 7_000  # the first message's receive time minus its sim time (0)
    for o in out:
        if o.topic == TF_TOPIC:
            ts = decoded(o).transforms[0].timestamp
            stamped_ns = ts.seconds * 1_000_000_000 + ts.nanos
            assert stamped_ns == o.log_time_ns
            sim_s = (o.log_time_ns - anchor) / 1e9
            assert abs(sim_s * 20 - round(sim_s * 20)) < 1e-6, sim_s  # on the 20 Hz grid
    stamps = [o.log_time_ns for o in out if o.topic == TF_TOPIC]
    assert all(b - a == 50_000_000 for a, b in itertools.pairwise(stamps))


def test_poses_locations_and_headings_are_those_of_the_states() -> None:
    scene = FoxgloveScene(None)
    out = fly(scene, 1.0, ["a", "b"])
    tf = decoded([o for o in out if o.topic == TF_TOPIC][-1])
    poses = {t.child_frame_id: t for t in tf.transforms}
    k = CONTROL_HZ - 6  # the last 20 Hz instant of the first second: tick 114
    assert poses["a"].parent_frame_id == "world"
    assert (poses["a"].translation.x, poses["a"].translation.y) == (0.1 * k, 2.0)
    assert math.isclose(poses["b"].translation.x, 0.1 * k + 1)
    loc = {o.topic: decoded(o) for o in out if o.topic.startswith("/location/")}
    a, b = loc[location_topic("a")], loc[location_topic("b")]
    assert (a.latitude, a.longitude, a.altitude) == (47.5, 8.5, 510.0)
    assert math.isclose(a.heading, math.pi / 2)  # nose east
    assert math.isclose(b.heading % (2 * math.pi), 0.0, abs_tol=1e-9)  # nose north


def test_readings_are_coloured_by_concentration_and_series_carry_nulls() -> None:
    sc = load_scenario(resolve_scenario_path(None))
    scene = FoxgloveScene(sc)
    low, high = 0.1 * scene.full_scale_g_m3, 0.9 * scene.full_scale_g_m3
    out = scene.feed(reading("uav_low", 0.0, low), WALL0_NS)
    out += scene.feed(reading("uav_high", 0.0, high), WALL0_NS)
    out += scene.feed(reading("uav_none", 0.0, None), WALL0_NS)
    states = [state(v, 24, 0.0, NORTH_XYZW) for v in ("uav_low", "uav_high", "uav_none")]
    tick = SimTick(tick=24, sim_time_s=0.2, control_dt_s=1 / CONTROL_HZ, states=states)
    out += scene.feed(tick, WALL0_NS + 200_000_000)  # the clock: the newest readings drawn
    spheres = {
        e.id: e.spheres[0] for o in out if o.topic == "/scene/readings" for e in decoded(o).entities
    }
    lo, hi = spheres["reading/uav_low"], spheres["reading/uav_high"]
    assert hi.color.r > lo.color.r and hi.color.b < lo.color.b  # redder with more gas
    assert hi.size.x > lo.size.x
    series = [decoded(o) for o in out if o.topic == concentration_topic("uav_none")]
    assert series and series[0]["reported_g_m3"] is None and not series[0]["available"]


def tetrahedron(level: float) -> PlumeMesh:
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], dtype="<f4")
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype="<i4")
    return PlumeMesh(level_g_m3=level, vertices_f32=v.tobytes(), faces_i32=f.tobytes())


def test_plume_isosurfaces_wait_for_the_clock_then_are_drawn_with_the_sources() -> None:
    sc = load_scenario(resolve_scenario_path(None))
    scene = FoxgloveScene(sc)
    assert scene.feed(tetrahedron(0.05), WALL0_NS) == []  # no sim time yet: nothing to stamp
    out = scene.feed(tetrahedron(0.01), WALL0_NS)
    out += fly(scene, 0.1, [v.id for v in sc.vehicles], sim0_s=3.0)
    plume = [o for o in out if o.topic == PLUME_TOPIC]
    assert len(plume) == 1
    entities = {e.id: e for e in decoded(plume[0]).entities}
    assert sum(i.startswith("source/") for i in entities) == len(sc.plume.sources)
    low = entities["plume/level_0"].triangles[0]  # the lower level first (the wider surface)
    assert len(low.points) == 4 and list(low.indices) == [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3]
    assert entities["plume/level_0"].metadata[0].value == "0.01"
    assert entities["plume/level_1"].triangles[0].color.a > low.color.a
    assert plume[0].log_time_ns == WALL0_NS + 7_000 + 3_000_000_000  # sim 3 s, anchored


def filament_states(*times_s: float) -> list[PlumeState]:
    """The ``field/state`` messages the plume service publishes for the bundled filament
    scenario at ``times_s``."""
    sc = load_scenario(resolve_scenario_path("filament"))
    publisher = StatePublisher(field_from_scenario(sc), sc.plume.state_period_s)
    return [publisher.state(t) for t in times_s]


def filaments_of(state: PlumeState) -> tuple[list[list[float]], list[float]]:
    centres = np.frombuffer(state.centres_f32, dtype="<f4").reshape(-1, 3)
    return centres.tolist(), np.frombuffer(state.radii_f32, dtype="<f4").tolist()


def plume_state_entity(o: Out) -> Any:
    (entity,) = decoded(o).entities
    return entity


def test_filaments_become_spheres_at_their_centres_and_each_state_replaces_the_last() -> None:
    sc = load_scenario(resolve_scenario_path("filament"))
    scene = FoxgloveScene(sc)
    early, skipped, later = filament_states(10.0, 10.25, 10.5)
    out = fly(scene, 0.1, [v.id for v in sc.vehicles], sim0_s=10.0)  # the clock: 10 s
    out += scene.feed(early, WALL0_NS + 10_300_000_000)
    out += scene.feed(skipped, WALL0_NS + 10_600_000_000)  # within 0.5 s: not drawn
    out += scene.feed(later, WALL0_NS + 10_800_000_000)
    frames = [o for o in out if o.topic == PLUME_STATE_TOPIC]
    assert len(frames) == 2
    anchor = WALL0_NS + 7_000  # fly() receives sim time t at WALL0_NS + t + 7 µs
    for o, state in zip(frames, (early, later), strict=True):
        centres, radii = filaments_of(state)
        assert 0 < len(radii) < PLUME_STATE_MAX_SPHERES
        entity = plume_state_entity(o)
        assert entity.id == "plume/state" and entity.frame_id == "world"  # one id: replaced
        assert {kv.key: kv.value for kv in entity.metadata}["count"] == str(len(radii))
        assert len(entity.spheres) == len(radii)
        for sphere, (x, y, z), r in zip(entity.spheres, centres, radii, strict=True):
            p = sphere.pose.position
            assert (p.x, p.y, p.z) == (x, y, z)
            assert sphere.size.x == sphere.size.z == max(2 * r, PLUME_STATE_MIN_DIAMETER_M)
        # the freshest (thinnest) filament is the densest: red; the oldest (widest) blue
        young = entity.spheres[radii.index(min(radii))]
        old = entity.spheres[radii.index(max(radii))]
        assert (young.color.r, young.color.b) == (1.0, 0.0)
        assert (old.color.r, old.color.b) == (0.0, 1.0)
        assert o.log_time_ns == anchor + round(state.sim_time_s * 1e9)  # its own sim time
        ts = entity.timestamp
        assert ts.seconds * 1_000_000_000 + ts.nanos == o.log_time_ns
    assert len(filaments_of(later)[1]) > len(filaments_of(early)[1])  # the plume grew


def test_a_crowded_plume_state_is_thinned_evenly_and_a_torn_one_draws_what_is_whole() -> None:
    scene = FoxgloveScene(None)
    n = 2 * PLUME_STATE_MAX_SPHERES + 1
    centres = np.stack([np.arange(n), np.zeros(n), np.full(n, 5.0)], axis=1).astype("<f4")
    radii = np.full(n, 0.5, dtype="<f4")
    crowded = PlumeState(
        sim_time_s=1.0,
        model="puff",
        count=n,
        centres_f32=centres.tobytes(),
        radii_f32=radii.tobytes(),
    )
    (o,) = scene.feed(crowded, WALL0_NS)  # the first sim time anchors the clock
    xs = [s.pose.position.x for s in plume_state_entity(o).spheres]
    assert PLUME_STATE_MAX_SPHERES / 2 < len(xs) <= PLUME_STATE_MAX_SPHERES
    steps = {b - a for a, b in itertools.pairwise(xs)}
    assert xs[0] == 0.0 and len(steps) == 1 and xs[-1] + steps.pop() > n - 1  # whole length
    assert all(s.size.x == 1.0 for s in plume_state_entity(o).spheres)
    torn = PlumeState(
        sim_time_s=2.0,
        model="filament",
        count=3,
        centres_f32=centres[:3].tobytes()[:-5],  # two whole centres
        radii_f32=radii[:3].tobytes(),
    )
    (o,) = scene.feed(torn, WALL0_NS + 1_000_000_000)
    assert [s.pose.position.x for s in plume_state_entity(o).spheres] == [0.0, 1.0]


def test_the_live_role_converts_the_plume_state_from_the_bus(tmp_path: Path) -> None:
    """The live role's conversion step on a real bus: a tick and a field/state published on a
    Zenoh session reach its Feed; what it sends through the SDK's channels is read back from
    an MCAP the SDK writes from the same context."""
    sc = load_scenario(resolve_scenario_path("filament"))
    keys = Keys(sc.world.name)
    (state,) = filament_states(10.0)
    tick = SimTick(tick=1200, sim_time_s=10.0, control_dt_s=1 / CONTROL_HZ, states=[])
    scene = FoxgloveScene(sc)
    context = foxglove.Context()
    channels = LiveChannels(context)
    path = tmp_path / "live.mcap"
    net = NetworkConfig(connect=[], listen=[f"tcp/127.0.0.1:{free_tcp_port()}"])
    with open_session(net) as session, foxglove.open_mcap(path, context=context):
        feed = Feed(session, keys)
        meshes = MeshFetcher(session, keys, [])
        try:
            session.put(keys.tick(), codec.encode(tick))
            session.put(keys.plume_state(), codec.encode(state))
            deadline = time.monotonic() + 10.0
            newest = -1
            while channels.sent < 2 or newest < 0:  # the vehicles' bodies and the plume state
                assert time.monotonic() < deadline, (
                    f"live: tick {newest}, {channels.sent} messages sent within 10 s"
                )
                newest = max(newest, convert(scene, feed, meshes, channels))
                time.sleep(0.05)
        finally:
            feed.close()
            meshes.close()
    frames = [update for _, update in topic_messages(path, PLUME_STATE_TOPIC)]
    assert newest == 1200 and len(frames) == 1
    centres, _ = filaments_of(state)
    spheres = frames[0].entities[0].spheres
    assert [[s.pose.position.x, s.pose.position.y, s.pose.position.z] for s in spheres] == centres


def test_every_message_decodes_against_the_schema_the_sdk_declares() -> None:
    sc = load_scenario(resolve_scenario_path(None))
    scene = FoxgloveScene(sc)
    out = scene.feed(tetrahedron(0.02), WALL0_NS)
    out += fly(scene, 1.5, [v.id for v in sc.vehicles])
    decoder = ChannelDecoder()
    seen = set()
    for o in out:
        cs = channel_schema(type(o.message))
        decoded = decoder.decode(cs.name, cs.encoding, cs.data, encode(o.message))
        seen.add(cs.name)
        if cs.name == "foxglove.FrameTransforms":
            assert {t.child_frame_id for t in decoded.transforms} == {v.id for v in sc.vehicles}
        if cs.name == "foxglove.LocationFix":
            assert decoded.latitude == 47.5
    assert seen == {
        "foxglove.FrameTransforms",
        "foxglove.SceneUpdate",
        "foxglove.LocationFix",
        "plumeswarm.ConcentrationSample",
    }


def test_the_layout_in_docs_is_the_one_made_for_the_bundled_scenario() -> None:
    sc = load_scenario(resolve_scenario_path(None))
    ids = [v.id for v in sc.vehicles]
    text = (REPO / "docs" / "foxglove-layout.json").read_text()
    assert text == layout_json(ids), "regenerate docs/foxglove-layout.json (see docs/recording.md)"
    layout = json.loads(text)
    panels = []
    stack = [layout["content"]]
    while stack:
        node = stack.pop()
        if node["type"] == "panel":
            panels.append(node)
        else:
            stack += [item["content"] for item in node["items"]]
    kinds = Counter(p["panelType"] for p in panels)
    assert kinds == {"ThreeDee": 1, "Map": 1, "Plot": len(ids)}
    plotted = {
        s["value"].split(".")[0] for p in panels if p["panelType"] == "Plot"
        for s in p["config"]["paths"]
    }  # fmt: skip
    assert plotted == {concentration_topic(v) for v in ids}
    three_d = next(p for p in panels if p["panelType"] == "ThreeDee")
    assert set(three_d["config"]["topics"]) == {
        VEHICLES_TOPIC, TRAILS_TOPIC, PLUME_TOPIC, PLUME_STATE_TOPIC, "/scene/readings"
    }  # fmt: skip


def write_segment(path: Path, ticks: range, wall0_ns: int, summary: bool) -> None:
    sink = McapSink(path, metadata={"world": "default"})
    keys = Keys("default")
    for k in ticks:
        states = [state("uav1", k, 0.1 * k, NORTH_XYZW)]
        tick = SimTick(
            tick=k, sim_time_s=k / CONTROL_HZ, control_dt_s=1 / CONTROL_HZ, states=states
        )
        sink.write_bus(keys.tick(), codec.encode(tick), wall0_ns + k * 1_000_000)
    sink.close({"received_total": str(len(ticks))} if summary else None)


def test_export_makes_each_segment_its_own_scene_as_the_recorder_did(tmp_path: Path) -> None:
    # Two segments (a recorder restarted): the second's ticks are received 5 s later.
    write_segment(tmp_path / "rec.mcap", range(0, 120), WALL0_NS, summary=True)
    later_ns = WALL0_NS + 5_000_000_000
    write_segment(tmp_path / "rec.1.mcap", range(300, 420), later_ns, summary=True)
    out = tmp_path / "out.mcap"
    done = export_foxglove(tmp_path / "rec.mcap", out)
    assert done.copied == 240 and done.vehicle_ids == ["uav1"] and not done.truncated
    with open(out, "rb") as f:
        reader = make_reader(f)
        tf = [m.log_time for _, c, m in reader.iter_messages() if c.topic == TF_TOPIC]
        summary = reader.get_summary()
        assert summary is not None
        meta = {r.name: r.metadata for r in reader.iter_metadata()}
    # Each segment's first /tf is stamped with the receive time of its first tick (its anchor).
    assert WALL0_NS in tf and later_ns + 300 * 1_000_000 in tf
    assert len(tf) == 2 * 20  # 1 s of sim per segment at 20 Hz
    assert meta["plumeswarm.summary"] == {"received_total": "120"}


def test_export_draws_the_recorded_plume_states(tmp_path: Path) -> None:
    """A recording of ticks and ``field/state`` (as the filament scenario's plume publishes it
    every 0.5 s of sim) exported: one plume-state frame per recorded state, each at its sim
    time, each the filaments of that state."""
    states = filament_states(1.0, 1.5, 2.0)
    sink = McapSink(tmp_path / "rec.mcap", metadata={"world": "filament"})
    keys = Keys("filament")
    for k in range(CONTROL_HZ, 2 * CONTROL_HZ + 1):
        tick = SimTick(tick=k, sim_time_s=k / CONTROL_HZ, control_dt_s=1 / CONTROL_HZ, states=[])
        sink.write_bus(keys.tick(), codec.encode(tick), WALL0_NS + k * 1_000_000)
        for st in states:
            if round(st.sim_time_s * CONTROL_HZ) == k:  # published once the clock reached it
                sink.write_bus(keys.plume_state(), codec.encode(st), WALL0_NS + k * 1_000_000 + 1)
    sink.close()
    export_foxglove(tmp_path / "rec.mcap", tmp_path / "out.mcap")
    frames = topic_messages(tmp_path / "out.mcap", PLUME_STATE_TOPIC)
    anchor = WALL0_NS + CONTROL_HZ * 1_000_000 - 1_000_000_000  # first tick (1 s) received − 1 s
    assert [t for t, _ in frames] == [anchor + round(st.sim_time_s * 1e9) for st in states]
    for (_, update), st in zip(frames, states, strict=True):
        centres, _ = filaments_of(st)
        drawn = [[s.pose.position.x, s.pose.position.y, s.pose.position.z]
                 for s in update.entities[0].spheres]  # fmt: skip
        assert drawn == centres


def test_export_refuses_to_overwrite_its_input(tmp_path: Path) -> None:
    write_segment(tmp_path / "rec.mcap", range(0, 12), WALL0_NS, summary=True)
    with pytest.raises(ExportError, match="is the recording being read"):
        export_foxglove(tmp_path / "rec.mcap", tmp_path / "rec.mcap")
