"""``plumeswarm export ros2 IN OUT_DIR``: a recording as a rosbag2 (MCAP storage, metadata.yaml,
bag version 9) with the topics of the ROS 2 bridge, in the same conversion
(:mod:`ros2_bridge.convert`), every message stamped with its sim time.

What each recorded bus message becomes:

- each ``sim/tick``: one ``/clock``, one ``/tf`` (every vehicle), one ``/<vehicle>/odom`` and
  one ``/<vehicle>/fix`` per vehicle;
- each ``vehicle/<id>/concentration``: one ``/<vehicle>/gas``; each ``vehicle/<id>/wind``: one
  ``/<vehicle>/wind``;
- each ``plume/mesh`` reply and each ``field/state``: one ``/plume/markers`` (the sources, the
  isosurfaces so far, the newest filaments or puffs).
"""

from __future__ import annotations

import logging
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Final

from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

from recorder.flight_log import scenario_of
from recorder.reader import ExportError, Recording
from ros2_bridge import convert as cv
from ros2_bridge import wire
from swarmbus.messages import (
    AnemometerReading,
    ConcentrationReading,
    PlumeMesh,
    PlumeState,
    SimTick,
)
from swarmbus.scenario import Scenario, load_scenario, resolve_scenario_path

log = logging.getLogger(__name__)
BAG_VERSION: Final = 9  # rosbag2's metadata version of Jazzy and Kilted


@dataclass(frozen=True)
class ExportedBag:
    written: int
    topics: int
    counts: dict[str, int]
    truncated: bool


@dataclass
class _Bag:
    writer: Writer
    connections: dict[str, Any] = field(default_factory=dict)
    counts: Counter[str] = field(default_factory=Counter)

    def write(self, topic: str, msgtype: str, message: Any, stamp_ns: int) -> None:
        conn = self.connections.get(topic)
        if conn is None:
            conn = self.writer.add_connection(topic, msgtype, typestore=wire.typestore())
            self.connections[topic] = conn
        self.writer.write(conn, stamp_ns, wire.encode(message, msgtype))
        self.counts[topic] += 1


@dataclass
class _Plume:
    scenario: Scenario
    meshes: list[PlumeMesh] = field(default_factory=list)
    state: PlumeState | None = None


def _write_tick(bag: _Bag, tick: SimTick) -> None:
    t_ns = cv.stamp_ns(tick.sim_time_s)
    bag.write("/clock", cv.CLOCK, cv.clock(tick.sim_time_s), t_ns)
    bag.write("/tf", cv.TF, cv.tf(tick.states), t_ns)
    for s in tick.states:
        bag.write(f"/{s.vehicle_id}/odom", cv.ODOM, cv.odometry(s), t_ns)
        bag.write(f"/{s.vehicle_id}/fix", cv.FIX, cv.nav_sat_fix(s), t_ns)


def _write(bag: _Bag, message: object, plume: _Plume, sim_time_s: float) -> float:
    """Write what ``message`` becomes; the sim time reached."""
    if isinstance(message, SimTick):
        _write_tick(bag, message)
        return message.sim_time_s
    if isinstance(message, ConcentrationReading):
        r = message
        bag.write(f"/{r.vehicle_id}/gas", cv.GAS, cv.gas(r), cv.stamp_ns(r.sim_time_s))
    elif isinstance(message, AnemometerReading):
        w = message
        bag.write(f"/{w.vehicle_id}/wind", cv.WIND, cv.wind(w), cv.stamp_ns(w.sim_time_s))
    elif isinstance(message, PlumeMesh | PlumeState):
        if isinstance(message, PlumeMesh):
            plume.meshes.append(message)
        else:
            plume.state = message
            sim_time_s = max(sim_time_s, message.sim_time_s)
        msg = cv.markers(plume.scenario, sim_time_s, plume.meshes, plume.state)
        bag.write("/plume/markers", cv.MARKERS, msg, cv.stamp_ns(sim_time_s))
    return sim_time_s


def export_ros2(src: str | Path, dst: Path) -> ExportedBag:
    """Write the bag ``dst`` (a directory that must not exist) from the recording ``src``.
    Raises :class:`ExportError` or :class:`~recorder.reader.RecordingError`."""
    recording = Recording.open(src)
    if dst.exists():
        raise ExportError(f"{dst}: exists; rosbag2 writes a new directory, choose another")
    scenario = scenario_of(recording) or load_scenario(resolve_scenario_path(None))
    writer = Writer(dst, version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
    try:
        writer.open()
    except (WriterError, OSError) as exc:
        raise ExportError(f"cannot write {dst}: {exc}") from None
    bag = _Bag(writer)
    plume = _Plume(scenario)
    sim_time_s = 0.0
    try:
        for rec in recording.messages():
            message = rec.message()
            if message is not None:
                sim_time_s = _write(bag, message, plume, sim_time_s)
    finally:
        writer.close()
    return ExportedBag(
        written=sum(bag.counts.values()),
        topics=len(bag.counts),
        counts=dict(bag.counts),
        truncated=recording.truncated,
    )
