"""Autopilot snapshots: a fresh autopilot restored from one is the same autopilot, attribute
for attribute, and flies on with the same bits (toy dynamics); the slot files survive a torn
write."""

from __future__ import annotations

import collections
import copy
import dataclasses
import enum
import math
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import pytest

from agents.autopilot import Autopilot
from agents.autopilot_node import NodeOptions, behavior_rng, build_autopilot
from agents.sensor import ConcentrationSensor
from agents.snapshot import SnapshotError, SnapshotSlots, VehicleSnapshot, capture, restore
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
from tests.agents_toy import ToyWorld

NOISY = NodeOptions(position_noise_m=0.05, velocity_noise_m_s=0.02)


def state_of(obj: Any, seen: set[int] | None = None) -> Any:
    """Every attribute reachable from ``obj`` as plain data (generators by their state;
    functions, bound methods and objects already visited left out)."""
    seen = set() if seen is None else seen
    if isinstance(obj, np.random.Generator):
        return obj.bit_generator.state
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


def fly(sc: Scenario, options: NodeOptions, flight: str) -> tuple[ToyWorld, Autopilot]:
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
    for cmd in (Arm(), MissionStart(start_index=0)):
        assert ap.handle(cmd).accepted
    w.run(10.0, until=lambda: w.vehicles["uav1"].p[2] > 3.0)
    assert ap.modes.mode == FlightMode.MISSION and ap.modes._climb_alt_m is not None


def casting_scenario() -> Scenario:
    sc = load_scenario()
    v = msgspec.structs.replace(
        sc.vehicles[0], spawn_enu_m=(45.0, 6.0, 0.0), behavior="agents.behaviors.casting:Casting"
    )
    return msgspec.structs.replace(sc, vehicles=[v])


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
    back = msgspec.msgpack.decode(wire, type=VehicleSnapshot)

    fresh_rng = behavior_rng(sc, "uav1")
    fresh = build_autopilot(sc, "uav1", NOISY, fresh_rng)
    fresh_sensor = ConcentrationSensor(sc.sensor, sc.world.seed, 0)
    assert state_of(fresh) != state_of(ap)  # the test can tell them apart
    restore(fresh, fresh_sensor, back, fresh_rng)
    assert state_of(fresh) == state_of(ap)
    assert state_of(fresh_sensor) == state_of(sensor)

    twin = copy.deepcopy(w)  # the same world, flown on by the restored autopilot
    twin.autopilots = {"uav1": fresh}
    twin.sensors = {"uav1": fresh_sensor}
    w.run(8.0)
    twin.run(8.0)
    assert twin.vehicles["uav1"].p.tolist() == w.vehicles["uav1"].p.tolist()
    assert twin.readings["uav1"] == w.readings["uav1"]
    assert state_of(fresh) == state_of(ap)
    assert math.dist(w.vehicles["uav1"].p, (0.0, 0.0, 0.0)) > 1.0  # it flew somewhere


def test_a_behaviour_whose_state_cannot_be_saved_is_named() -> None:
    sc = casting_scenario()
    ap = build_autopilot(sc, "uav1", NodeOptions())
    ap.behavior.opaque = object()  # type: ignore[union-attr]
    with pytest.raises(SnapshotError, match=r"Casting.*snapshot\(\) and restore"):
        capture(ap, ConcentrationSensor(sc.sensor, 0, 0))


def test_slots_keep_the_previous_record_when_the_newest_is_torn(tmp_path: Path) -> None:
    slots = SnapshotSlots(tmp_path / "ap.state")
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
    again = SnapshotSlots(tmp_path / "ap.state")
    again.open()  # a restarted writer goes on after the records it found
    again.write(b"next")
    assert next(p for _, p in again.read_all()) == b"next"
    again.close()
