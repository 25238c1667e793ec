"""Autopilot checkpoints: a fresh autopilot restored from one is the same autopilot, attribute
for attribute, and flies on with the same bits (toy dynamics); the slot files survive a torn
write."""

from __future__ import annotations

import collections
import copy
import dataclasses
import enum
import importlib
import inspect
import math
import pkgutil
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

import agents.behaviors
from agents.autopilot import Autopilot
from agents.build import AutopilotOptions, behavior_rng, build_autopilot
from agents.checkpoint import CheckpointError, VehicleCheckpoint, capture, restore
from agents.checkpoint_store import CheckpointSlots
from agents.sensor import ConcentrationSensor
from plume_service import GaussianPlume
from swarmbus.messages import (
    Arm,
    FenceZone,
    FlightMode,
    GcsHeartbeat,
    GeofenceUpload,
    MissionCommand,
    MissionItem,
    MissionStart,
    MissionUpload,
    Orbit,
    RallyUpload,
    ReturnToLaunch,
    SetMode,
    SetParam,
    Takeoff,
)
from swarmbus.scenario import Scenario, load_scenario
from tests.support.toy_physics import ToyWorld

NOISY = AutopilotOptions(position_noise_m=0.05, velocity_noise_m_s=0.02)


def state_of(obj: Any, seen: set[int] | None = None) -> Any:
    """Every attribute reachable from ``obj`` as plain data (generators by their state;
    functions, bound methods and objects already visited left out)."""
    seen = set() if seen is None else seen
    if isinstance(obj, np.random.Generator):
        return obj.bit_generator.state
    if isinstance(obj, np.ndarray):
        return [obj.dtype.str, obj.shape, obj.tobytes()]
    if isinstance(obj, (str, int, float, bool, type(None), enum.Enum, bytes)):
        return obj
    if isinstance(obj, (list, tuple, collections.deque)):
        return [state_of(v, seen) for v in obj]
    if isinstance(obj, dict):
        return {k: state_of(v, seen) for k, v in obj.items() if not callable(v)}
    if isinstance(obj, msgspec.Struct):
        return msgspec.to_builtins(obj)
    if id(obj) in seen:
        return "<seen>"
    seen.add(id(obj))
    if dataclasses.is_dataclass(obj):
        names = [f.name for f in dataclasses.fields(obj)]
    elif hasattr(obj, "__dict__"):
        names = list(vars(obj))
    else:
        names = [n for c in type(obj).__mro__ for n in getattr(c, "__slots__", ())]
    return {n: state_of(getattr(obj, n), seen) for n in names if not callable(getattr(obj, n))}


def fly(sc: Scenario, options: AutopilotOptions, flight: str) -> tuple[ToyWorld, Autopilot]:
    ap = build_autopilot(sc, "uav1", options, behavior_rng(sc, "uav1"))
    field = GaussianPlume.preset("novak2018").concentration
    w = ToyWorld(sc, {"uav1": ap}, field=field)
    w.run(0.05)
    assert ap.handle(GcsHeartbeat()).accepted
    assert ap.handle(SetParam(name="COM_DL_LOSS_T", value=600.0)).accepted
    if flight == "px4":
        fly_px4(w, ap)
    elif flight == "casting":
        for cmd in (Arm(), Takeoff(altitude_m=10.0)):
            assert ap.handle(cmd).accepted
        w.run(20.0, until=lambda: ap.modes.mode == FlightMode.HOLD)
        assert ap.handle(SetMode(mode=FlightMode.OFFBOARD)).accepted
        w.run(15.0)
        assert ap.modes.mode == FlightMode.OFFBOARD
    else:
        assert ap.handle(Arm()).accepted
        assert ap.handle(MissionStart(start_index=0)).accepted
        w.run(60.0, until=lambda: ap.modes.mission.index >= 2)
        w.run(0.4)  # somewhere between items
        assert ap.modes.mode == FlightMode.MISSION
    return w, ap


def fly_px4(w: ToyWorld, ap: Autopilot) -> None:
    """Fence zones and a rally point uploaded, an orbit, RTL to the rally point (closer than
    home), then a mission without a take-off item started on the ground: caught while it
    climbs, with every piece of that state different from a fresh autopilot's."""
    zones = [
        FenceZone(center_enu_m=(20.0, -4.0), radius_m=60.0),
        FenceZone(inclusion=False, center_enu_m=(-30.0, -4.0), radius_m=5.0),
    ]
    rally = (30.0, 2.0, 0.0)
    assert ap.handle(GeofenceUpload(zones=zones)).accepted
    assert ap.handle(RallyUpload(points_enu_m=[rally])).accepted
    for cmd in (Arm(), Takeoff(altitude_m=10.0)):
        assert ap.handle(cmd).accepted
    w.run(20.0, until=lambda: ap.modes.mode == FlightMode.HOLD)
    assert ap.handle(Orbit(center_enu_m=(25.0, -4.0, 10.0), radius_m=5.0, speed_m_s=2.0)).accepted
    w.run(5.0)
    assert ap.modes.mode == FlightMode.ORBIT
    assert ap.handle(ReturnToLaunch()).accepted
    w.run(60.0, until=lambda: ap.modes.mode == FlightMode.DISARMED)
    assert math.dist(w.vehicles["uav1"].p[:2], rally[:2]) < 1.5  # landed at the rally point
    items = [
        MissionItem(x=35.0, y=10.0, z=8.0),
        MissionItem(command=MissionCommand.LAND, x=35.0, y=10.0, z=0.0),
    ]
    assert ap.handle(MissionUpload(items=items)).accepted
    for start in (Arm(), MissionStart(start_index=0)):
        assert ap.handle(start).accepted
    w.run(10.0, until=lambda: w.vehicles["uav1"].p[2] > 3.0)
    assert ap.modes.mode == FlightMode.MISSION and ap.modes._climb_altitude_m is not None


def casting_scenario(behavior: str = "agents.behaviors.casting:Casting") -> Scenario:
    sc = load_scenario()
    v = msgspec.structs.replace(sc.vehicles[0], spawn_enu_m=(45.0, 6.0, 0.0), behavior=behavior)
    return msgspec.structs.replace(sc, vehicles=[v])


def every_behavior() -> list[str]:
    """``module:Class`` of every behaviour in agents/behaviors (a concrete class with a step
    method; an abstract base such as ``SeekingBehavior`` is none)."""
    specs = []
    for info in pkgutil.iter_modules(agents.behaviors.__path__):
        module = importlib.import_module(f"agents.behaviors.{info.name}")
        for name, cls in inspect.getmembers(module, inspect.isclass):
            concrete = not inspect.isabstract(cls)
            if (
                cls.__module__ == module.__name__
                and concrete
                and callable(getattr(cls, "step", None))
            ):
                specs.append(f"{module.__name__}:{name}")
    return sorted(specs)


BEHAVIORS = every_behavior()
#: The particle filter with its correlation-aware likelihood (its windows' winds are state too).
EFFECTIVE_PF = (
    "plumeswarm.gsl.tuned:agents.behaviors.particle_filter:ParticleFilter"
    '?{"likelihood":"effective"}'
)


@pytest.mark.parametrize(
    "flight", ["mission", "casting", "px4"], ids=["mission", "offboard-casting", "px4"]
)
def test_a_restored_autopilot_is_the_same_and_flies_the_same_bits(flight: str) -> None:
    sc = casting_scenario() if flight == "casting" else load_scenario()
    w, ap = fly(sc, NOISY, flight)
    sensor = w.sensors["uav1"]
    ap.modes.mission.drain_events()  # as the node does after every step (they are log lines)
    rng = ap.behavior.__dict__.get("rng") if ap.behavior else None  # Casting keeps none
    snap = capture(ap, sensor, rng)
    wire = msgspec.msgpack.encode(snap)
    back = msgspec.msgpack.decode(wire, type=VehicleCheckpoint)

    fresh_rng = behavior_rng(sc, "uav1")
    fresh = build_autopilot(sc, "uav1", NOISY, fresh_rng)
    fresh_sensor = ConcentrationSensor(sc.sensor, sc.world.seed, 0)
    assert state_of(fresh) != state_of(ap)  # the test can tell them apart
    restore(fresh, fresh_sensor, back, fresh_rng)
    assert state_of(fresh) == state_of(ap)
    assert state_of(fresh_sensor) == state_of(sensor)

    fly_on_together(w, ap, fresh, fresh_sensor)
    assert math.dist(w.vehicles["uav1"].p, (0.0, 0.0, 0.0)) > 1.0  # it flew somewhere


def fly_on_together(
    w: ToyWorld, ap: Autopilot, fresh: Autopilot, fresh_sensor: ConcentrationSensor
) -> None:
    """``w`` and a copy of it flown by the restored autopilot: 8 s later, the same bits."""
    twin = copy.deepcopy(w)
    twin.autopilots = {"uav1": fresh}
    twin.sensors = {"uav1": fresh_sensor}
    w.run(8.0)
    twin.run(8.0)
    assert twin.vehicles["uav1"].p.tolist() == w.vehicles["uav1"].p.tolist()
    assert twin.readings["uav1"] == w.readings["uav1"]
    assert state_of(fresh) == state_of(ap)


def test_every_gsl_algorithm_is_among_the_behaviours_checked() -> None:
    from plumeswarm.gsl.registry import BUILTIN_ALGORITHMS as ALGORITHMS

    assert {a.behavior for a in ALGORITHMS.values()} <= set(BEHAVIORS)
    assert len(BEHAVIORS) >= 6


@pytest.mark.parametrize(
    "spec",
    [*BEHAVIORS, EFFECTIVE_PF],
    ids=[*(s.rpartition(":")[2] for s in BEHAVIORS), "ParticleFilter-effective"],
)
def test_every_behaviour_is_restored_and_flies_on_with_the_same_bits(spec: str) -> None:
    """Each behaviour flown offboard for 15 s, captured, restored into a fresh autopilot (its
    own generator, its own sensor): the two fly on for 8 s to the same bits."""
    sc = casting_scenario(spec)
    w, ap = fly(sc, NOISY, "casting")
    sensor = w.sensors["uav1"]
    ap.modes.mission.drain_events()
    gens = [v for v in vars(ap.behavior).values() if isinstance(v, np.random.Generator)]
    rng = gens[0] if gens else None  # the context's generator, if the behaviour draws from it
    wire = msgspec.msgpack.encode(capture(ap, sensor, rng))
    snap = msgspec.msgpack.decode(wire, type=VehicleCheckpoint)
    assert snap.behavior is not None
    saved = msgspec.msgpack.decode(snap.behavior.data)
    assert "read_wind" not in saved  # the wind input is wiring, not state

    fresh_rng = behavior_rng(sc, "uav1")
    fresh = build_autopilot(sc, "uav1", NOISY, fresh_rng)
    fresh_sensor = ConcentrationSensor(sc.sensor, sc.world.seed, 0)
    assert state_of(fresh.behavior) != state_of(ap.behavior)  # the test can tell them apart
    restore(fresh, fresh_sensor, snap, fresh_rng)
    assert state_of(fresh) == state_of(ap)

    fly_on_together(w, ap, fresh, fresh_sensor)
    assert math.dist(w.vehicles["uav1"].p[:2], (45.0, 6.0)) > 1.0  # it flew somewhere


class HoldsAFunction:
    """A behaviour without checkpoint() whose attributes are not plain data."""

    def __init__(self) -> None:
        self.read_wind = lambda own: (5.0, 0.0)

    def step(self, *args: Any) -> None:
        return None


def test_a_behaviour_whose_state_cannot_be_saved_is_named() -> None:
    sc = casting_scenario()
    ap = build_autopilot(sc, "uav1", AutopilotOptions())
    ap.behavior = HoldsAFunction()
    with pytest.raises(CheckpointError, match=r"HoldsAFunction.*checkpoint\(\) and restore"):
        capture(ap, ConcentrationSensor(sc.sensor, 0, 0))
    ap.behavior = build_autopilot(sc, "uav1", AutopilotOptions()).behavior
    ap.behavior.opaque = object()
    with pytest.raises(CheckpointError, match=r"Casting.*checkpoint\(\) and restore"):
        ap.behavior.state_attributes = ("opaque",)
        capture(ap, ConcentrationSensor(sc.sensor, 0, 0))


class SavesWithTheOldName:
    """A behaviour written against the old plug-in names: snapshot() / restore(data)."""

    def __init__(self) -> None:
        self.count = 7

    def step(self, *args: Any) -> None:
        return None

    def snapshot(self) -> dict[str, Any]:
        return {"count": self.count}

    def restore(self, data: dict[str, Any]) -> None:
        self.count = data["count"]


def test_a_behaviours_old_snapshot_method_is_still_saved_with_one_deprecation_line(
    caplog: pytest.LogCaptureFixture,
) -> None:
    sc = casting_scenario()
    ap = build_autopilot(sc, "uav1", AutopilotOptions())
    ap.behavior = SavesWithTheOldName()
    sensor = ConcentrationSensor(sc.sensor, 0, 0)
    saved = [capture(ap, sensor) for _ in range(3)]
    assert all(s.behavior is not None for s in saved)
    assert msgspec.msgpack.decode(saved[0].behavior.data) == {"count": 7}
    lines = [r.getMessage() for r in caplog.records if "SavesWithTheOldName" in r.getMessage()]
    assert lines == [
        "behaviour SavesWithTheOldName: snapshot() is deprecated, name it checkpoint(); it is "
        "called as checkpoint() until the next release"
    ]
    fresh = build_autopilot(sc, "uav1", AutopilotOptions())
    fresh.behavior = SavesWithTheOldName()
    fresh.behavior.count = 0
    restore(fresh, ConcentrationSensor(sc.sensor, 0, 0), saved[0])
    assert fresh.behavior.count == 7


def test_an_old_snapshot_override_on_saves_state_is_not_bypassed(
    caplog: pytest.LogCaptureFixture,
) -> None:
    from agents.behavior_state import SavesState

    class AddsToItsState(SavesState):
        state_attributes = ("count",)

        def __init__(self) -> None:
            self.count = 3

        def step(self, *args: Any) -> None:
            return None

        def snapshot(self) -> dict[str, Any]:
            return {**self.checkpoint(), "extra": 1}

    sc = casting_scenario()
    ap = build_autopilot(sc, "uav1", AutopilotOptions())
    ap.behavior = AddsToItsState()
    saved = capture(ap, ConcentrationSensor(sc.sensor, 0, 0))
    assert saved.behavior is not None
    assert msgspec.msgpack.decode(saved.behavior.data) == {"count": 3, "extra": 1}
    assert any("AddsToItsState: snapshot() is deprecated" in r.getMessage() for r in caplog.records)


def test_slots_keep_the_previous_record_when_the_newest_is_torn(tmp_path: Path) -> None:
    slots = CheckpointSlots(tmp_path / "ap.state")
    slots.open()
    for k in range(5):
        slots.write(f"record {k}".encode() * (k + 1))
    assert [p for _, p in slots.read_all()] == [b"record 4" * 5, b"record 3" * 4]
    newest = next(p for p in slots.paths() if b"record 4" in p.read_bytes())
    data = bytearray(newest.read_bytes())
    data[-3] ^= 0xFF  # a write cut short by a kill
    newest.write_bytes(bytes(data))
    assert [p for _, p in slots.read_all()] == [b"record 3" * 4]
    slots.close()
    again = CheckpointSlots(tmp_path / "ap.state")
    again.open()  # a restarted writer goes on after the records it found
    again.write(b"next")
    assert next(p for _, p in again.read_all()) == b"next"
    again.close()


def test_saved_state_comes_back_with_the_same_types_and_bits() -> None:
    """An own generator (mid-stream, with a cached 32-bit half), arrays, deques of tuples,
    an estimate and a nested helper survive msgpack; configuration is left as built."""
    from agents.behavior import SourceEstimate
    from agents.behavior_state import SavesState
    from agents.behaviors.steering import CrosswindSweep

    class Holder(SavesState):
        state_attributes = ("gen", "grid", "trail", "estimate", "sweep", "counts")

        def __init__(self, seed: int, speed: float) -> None:
            self.speed = speed  # configuration: not saved
            self.gen = np.random.default_rng(seed)
            self.grid = np.zeros((0, 2))
            self.trail: collections.deque[tuple[float, float]] = collections.deque()
            self.estimate: SourceEstimate | None = None
            self.sweep = CrosswindSweep(2.0, 0.5, 5.0, 1.6)
            self.counts: dict[str, list[int]] = {}

    a = Holder(7, 1.0)
    a.gen.random(3)
    a.gen.integers(0, 10, dtype=np.uint32)  # leaves a cached half word in the state
    a.grid = a.gen.normal(size=(4, 2)).astype(np.float32)
    a.trail.extend([(0.1, 0.2), (0.3, 1e-300)])
    a.estimate = SourceEstimate(x_m=1.5, y_m=-2.0, sim_time_s=3.0, spread_m=0.25)
    a.sweep.side, a.sweep.anchor_across_m, a.sweep.half_width_m = -1.0, 4.0, 8.0
    a.counts = {"hits": [1, 2]}
    data = msgspec.msgpack.decode(msgspec.msgpack.encode(a.checkpoint()))
    b = Holder(99, 2.0)
    b.restore(data)
    assert b.speed == 2.0
    assert b.grid.dtype == np.float32 and b.grid.tobytes() == a.grid.tobytes()
    assert b.trail == a.trail and isinstance(b.trail, collections.deque)
    assert b.estimate == a.estimate and b.counts == a.counts
    assert state_of(b.sweep) == state_of(a.sweep)
    assert b.gen.integers(0, 10, dtype=np.uint32) == a.gen.integers(0, 10, dtype=np.uint32)
    assert b.gen.random(5).tobytes() == a.gen.random(5).tobytes()
    with pytest.raises(ValueError, match="'grid'"):
        Holder(0, 1.0).restore({k: v for k, v in data.items() if k != "grid"})


def test_each_mission_is_encoded_once_however_many_vehicles_a_process_serves() -> None:
    """Every tick's checkpoint holds each served vehicle's mission; a mission list (replaced on
    upload, never changed in place) is encoded once while it is in use — here 300 vehicles'
    missions asked for in turn, tick after tick, each answered with its first encoding."""
    from agents.checkpoint import _items_raw

    missions = [[MissionItem(x=float(v), y=float(i), z=10.0) for i in range(5)] for v in range(300)]
    first = [_items_raw(items) for items in missions]
    for _ in range(3):
        assert all(_items_raw(items) is raw for items, raw in zip(missions, first, strict=True))
    decoded = [msgspec.msgpack.decode(raw, type=list[MissionItem]) for raw in first]
    assert decoded == missions
    assert msgspec.msgpack.decode(_items_raw([]), type=list[MissionItem]) == []


def _uploaded(items: int, vertices: int) -> Autopilot:
    sc = load_scenario()
    ap = build_autopilot(sc, "uav1", AutopilotOptions())
    mission = [MissionItem(x=float(i % 50), y=float(i // 50), z=10.0) for i in range(items)]
    assert ap.handle(MissionUpload(items=mission)).accepted
    ring = [
        (200.0 * math.cos(2 * math.pi * k / vertices), 200.0 * math.sin(2 * math.pi * k / vertices))
        for k in range(vertices)
    ]
    assert ap.handle(GeofenceUpload(zones=[FenceZone(polygon_enu_m=ring)])).accepted
    return ap


def test_a_ticks_checkpoint_does_not_grow_with_the_mission_or_the_fence() -> None:
    """Missions and fences are saved by reference: a vehicle's checkpoint with 1000 mission
    items and a 200-vertex fence is as long as one with 2 items and a triangle (it was
    ≈ 60 kB longer when the lists were in every tick's record)."""
    sc = load_scenario()
    small, large = _uploaded(2, 3), _uploaded(1000, 200)
    size = [
        len(msgspec.msgpack.encode(capture(ap, ConcentrationSensor(sc.sensor, 0, 0))))
        for ap in (small, large)
    ]
    assert size[1] == size[0]
    back = msgspec.msgpack.decode(
        msgspec.msgpack.encode(capture(large, ConcentrationSensor(sc.sensor, 0, 0))),
        type=VehicleCheckpoint,
    )
    fresh = build_autopilot(sc, "uav1", AutopilotOptions())
    restore(fresh, ConcentrationSensor(sc.sensor, 0, 0), back)
    assert fresh.modes.mission.items == large.modes.mission.items
    assert len(fresh.modes.mission.items) == 1000
    assert fresh.modes.fence_zones == large.modes.fence_zones


def test_the_blob_log_gives_a_restarted_process_its_lists_and_survives_a_torn_append(
    tmp_path: Path,
) -> None:
    """A new process (its own Blobs) reads the lists back by their keys; an append cut short
    by a kill is cut off, and what is appended after it reads back."""
    from agents.checkpoint_store import BlobLog, Blobs

    path = tmp_path / "ap.state.blobs"
    first = Blobs()
    log = BlobLog(path, first)
    log.open()
    lists = [[MissionItem(x=float(v), y=float(i), z=5.0) for i in range(v + 1)] for v in range(4)]
    keys = [first.encoded(items)[1] for items in lists]
    log.flush()
    size = path.stat().st_size
    log.flush()  # nothing new: nothing written
    assert path.stat().st_size == size
    first.encoded([MissionItem(x=9.0, y=9.0, z=9.0)])
    log.flush()
    log.close()
    data = path.read_bytes()
    path.write_bytes(data[:-5])  # the last append cut short

    second = Blobs()
    again = BlobLog(path, second)
    again.open()
    assert set(second.by_key) == set(keys)
    for key, items in zip(keys, lists, strict=True):
        assert msgspec.msgpack.decode(second.by_key[key], type=list[MissionItem]) == items
    assert path.stat().st_size == size  # the torn record is cut off
    late = second.encoded([MissionItem(x=1.0, y=2.0, z=3.0)])[1]
    again.flush()
    again.close()
    third = Blobs()
    last = BlobLog(path, third)
    last.open()
    last.close()
    assert set(third.by_key) == {*keys, late}


def test_a_restarted_keeper_restores_only_checkpoints_whose_lists_it_has(tmp_path: Path) -> None:
    from agents.checkpoint import ProcessCheckpoint
    from agents.resume import StateKeeper

    sc = load_scenario()
    v = capture(_uploaded(300, 12), ConcentrationSensor(sc.sensor, 0, 0))
    lost = msgspec.structs.replace(v, scenario_mission="0" * 32)  # a list never saved

    def record(tick: int, vehicle: VehicleCheckpoint) -> bytes:
        snap = ProcessCheckpoint(
            node="ap",
            tick=tick,
            vehicles=[vehicle],
            commands=[b""],
            status_times_s=[0.0],
            pending=None,
        )
        return msgspec.msgpack.encode(snap)

    keeper = StateKeeper(tmp_path / "ap.state", 0)
    keeper.open(record(-1, v))
    keeper.save(record(4, v))
    keeper.save(record(5, lost))
    keeper.close()
    again = StateKeeper(tmp_path / "ap.state", 0)
    again.open(record(-1, v))
    restored = again.for_restart(5)
    assert restored is not None and restored.tick == 4
    assert restored.vehicles[0].modes.mission.items == v.modes.mission.items
    assert again.for_restart(6) is None  # tick 5 refers to a missing list
    again.close()
    assert (tmp_path / "ap.state.blobs").stat().st_size > 300 * 20  # the mission, once
