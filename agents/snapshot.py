"""Snapshots of an autopilot's state, so a restarted autopilot carries on exactly where it was.

A :class:`VehicleSnapshot` holds everything of one vehicle's :class:`~agents.autopilot.Autopilot`
that influences its future: mode, arming, home, targets, the mission and its current item (and
the hold timer of that item, and the climb of a mission started on the ground), the offboard
setpoint, its time and the last offboard tick (yaw-rate setpoints integrate over it), the RTL
phase and destination, the uploaded geofence zones and rally points, the orbit, the failsafe
configuration (parameters may have been set) and its timers, the controller's integrators and
derivative memory, the last state and estimate, the estimator's and the sensor's random
generators, the sensor's lag, and the behaviour plug-in's state with its generator. Restoring
it into a freshly built autopilot of the same scenario makes the next tick's command the same
bits as the killed process would have sent (``tests/agents/test_agents_snapshot.py`` checks every
attribute and the commands).

A behaviour is saved with its ``snapshot()`` / ``restore(data)`` methods when it has them
(``snapshot`` returns msgpack-encodable data; the behaviours in :mod:`agents.behaviors` get
them from :class:`agents.behavior_state.SavesState`), otherwise as its attributes (numbers,
strings, tuples, lists, dicts, ``None``), which covers plain-data behaviours; its context's
generator is saved separately. A
behaviour whose state cannot be saved makes :func:`capture` raise :class:`SnapshotError`.

:class:`SnapshotSlots` keeps the latest two records of a process in two files written in turn
(one ``pwritev`` each, a CRC-32 over the record): a process killed in the middle of a write
leaves the other file intact, and a reader takes the newest valid one. Nothing is pickled.

Mission item lists and fence zone lists change only on an upload, which replaces the list (they
are never changed in place), but a process saves a snapshot every tick. So a snapshot holds
them by reference: each list is encoded once, named by a digest of its encoding and kept in
:data:`BLOBS`; :class:`BlobLog` appends each new one to a log file once (before the first
snapshot that refers to it is written) and gives them back to a restarted process. A tick's
record is therefore the same size whatever the missions' lengths.
"""

from __future__ import annotations

import hashlib
import os
import struct
import zlib
from collections import OrderedDict
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import msgspec
import numpy as np

from agents.control import Estimate
from agents.modes import RtlPhase
from swarmbus.messages import FenceZone, FlightMode, MissionItem, Orbit, Setpoint, VehicleState
from swarmbus.scenario import Failsafe

if TYPE_CHECKING:
    from agents.autopilot import Autopilot
    from agents.sensor import ConcentrationSensor

FORMAT = "autopilot_snapshot/v3"
Vec3 = tuple[float, float, float]


class SnapshotError(ValueError):
    """A snapshot that cannot be taken, read or restored; the message says which and why."""


class RngState(msgspec.Struct, frozen=True, array_like=True):
    """A numpy PCG64 generator's state (the 128-bit words as decimal strings)."""

    state: str
    inc: str
    has_uint32: int
    uinteger: int


def rng_state(rng: np.random.Generator) -> RngState:
    st = rng.bit_generator.state
    if st["bit_generator"] != "PCG64":
        raise SnapshotError(f"cannot save a {st['bit_generator']} generator (PCG64 only)")
    return RngState(
        str(st["state"]["state"]), str(st["state"]["inc"]), st["has_uint32"], st["uinteger"]
    )


def set_rng_state(rng: np.random.Generator, saved: RngState) -> None:
    rng.bit_generator.state = {
        "bit_generator": "PCG64",
        "state": {"state": int(saved.state), "inc": int(saved.inc)},
        "has_uint32": saved.has_uint32,
        "uinteger": saved.uinteger,
    }


class ControllerSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    vel_integral: list[float]
    rate_integral: list[float]
    velocity_prev: Vec3 | None
    rates_prev: Vec3 | None


class MissionSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    items: str  # list[MissionItem], by reference (BLOBS)
    index: int
    items_reached: int
    finished: bool
    hold_started_s: float | None


class ModesSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    mode: FlightMode
    failsafe: Failsafe
    home: Vec3
    failsafe_reason: str
    target: Vec3
    yaw_rad: float
    speed_m_s: float
    touchdown_since_s: float | None
    rtl_phase: str
    rtl_alt_m: float
    setpoint: Setpoint | None
    setpoint_time_s: float
    item_seen: int
    land_descending: bool
    mission: MissionSnapshot
    fence_zones: str  # list[FenceZone], by reference (BLOBS)
    rally_points: list[Vec3]
    rtl_dest: Vec3
    offboard_tick_s: float
    climb_alt_m: float | None
    orbit: Orbit | None


class MonitorSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    gcs_seen: bool
    last_gcs_s: float
    datalink_lost: bool
    outside_fence: bool
    crashed: bool


class SensorSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    """The sensor's state, whichever of these its model keeps (the others are None)."""

    lagged_g_m3: float | None
    last_time_s: float | None
    rng: RngState | None  # a sensor that draws its noise from a running generator
    history: list[tuple[float, float]] | None = None  # (sim time, lag state) of recent samples


class BehaviorSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    data: msgspec.Raw  # the behaviour's snapshot() or its attributes, msgpack
    rng: RngState | None


class VehicleSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    vehicle_id: str
    now_s: float
    state: VehicleState | None
    estimate: Estimate | None
    scenario_mission: str  # list[MissionItem], by reference (BLOBS)
    behavior_error: str
    sensor_health: str
    modes: ModesSnapshot
    monitor: MonitorSnapshot
    controller: ControllerSnapshot
    estimator_rng: RngState | None  # None: no noise, the generator is never drawn from
    sensor: SensorSnapshot
    behavior: BehaviorSnapshot | None


# ---------------------------------------------------------------------------- capture
class Blobs:
    """Encoded lists (missions, fence zones) by the digest of their encoding, in the order they
    were first seen. A list is replaced on upload, never changed in place, so it is encoded
    once while it is in use: a cache by the list's identity (holding the list keeps its id from
    being reused while it is cached) answers every later tick. Least recently used first out:
    the lists a process's vehicles fly are asked for every tick and stay; a replaced one is
    never asked for again and goes first. The encodings themselves stay (a snapshot kept for a
    rewind may still refer to one); they grow with uploads only."""

    def __init__(self, cache_size: int = 1024) -> None:
        self.by_key: dict[str, msgspec.Raw] = {}
        self.order: list[str] = []  # keys in the order they were first seen
        self._cache: OrderedDict[int, tuple[list[Any], msgspec.Raw, str]] = OrderedDict()
        self._cache_size = cache_size

    def add(self, raw: msgspec.Raw | bytes) -> str:
        """The key of an encoding (kept if new)."""
        key = hashlib.blake2b(bytes(raw), digest_size=16).hexdigest()
        if key not in self.by_key:
            self.by_key[key] = msgspec.Raw(bytes(raw))
            self.order.append(key)
        return key

    def encoded(self, items: list[Any]) -> tuple[msgspec.Raw, str]:
        """``items`` encoded, and its key: once per list."""
        ident = id(items)
        hit = self._cache.get(ident)
        if hit is not None and hit[0] is items:
            self._cache.move_to_end(ident)
            return hit[1], hit[2]
        raw = msgspec.Raw(msgspec.msgpack.encode(items))
        key = self.add(raw)
        self._cache[ident] = (items, raw, key)
        self._cache.move_to_end(ident)
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return raw, key

    def get(self, key: str, what: str) -> msgspec.Raw:
        raw = self.by_key.get(key)
        if raw is None:
            raise SnapshotError(f"{what}: the saved list {key} is missing") from None
        return raw


#: Every encoded mission and fence list of this process (see :class:`Blobs`).
BLOBS = Blobs()
_NO_ITEMS = msgspec.Raw(msgspec.msgpack.encode([]))
_NO_ITEMS_KEY = BLOBS.add(_NO_ITEMS)
_items_decoder = msgspec.msgpack.Decoder(list[MissionItem])
_zones_decoder = msgspec.msgpack.Decoder(list[FenceZone])


def _items_raw(items: list[MissionItem]) -> msgspec.Raw:
    """``items`` encoded, once per list (an empty list: one shared encoding)."""
    return _NO_ITEMS if not items else BLOBS.encoded(items)[0]


def _ref(items: list[Any]) -> str:
    return _NO_ITEMS_KEY if not items else BLOBS.encoded(items)[1]


def _items_of(key: str) -> list[MissionItem]:
    try:
        return _items_decoder.decode(BLOBS.get(key, "mission items"))
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise SnapshotError(f"mission items: {exc}") from None


def _zones_of(key: str) -> list[FenceZone]:
    try:
        return _zones_decoder.decode(BLOBS.get(key, "fence zones"))
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise SnapshotError(f"fence zones: {exc}") from None


def capture(
    ap: Autopilot,
    sensor: ConcentrationSensor,
    behavior_rng: np.random.Generator | None = None,
) -> VehicleSnapshot:
    """Everything of ``ap`` (and its sensor) that influences its future, as of now."""
    m, c, mon = ap.modes, ap.controller, ap.monitor
    mission = m.mission
    return VehicleSnapshot(
        vehicle_id=ap.vehicle_id,
        now_s=ap.now,
        state=ap.state,
        estimate=ap.est,
        scenario_mission=_ref(ap._scenario_mission),
        behavior_error=ap.behavior_error,
        sensor_health=ap.sensor_health,
        modes=ModesSnapshot(
            mode=m.mode,
            failsafe=m.failsafe,
            home=m.home,
            failsafe_reason=m.failsafe_reason,
            target=m._target,
            yaw_rad=m._yaw,
            speed_m_s=m._speed,
            touchdown_since_s=m._touchdown_since,
            rtl_phase=m._rtl_phase.value,
            rtl_alt_m=m._rtl_alt,
            setpoint=m._setpoint,
            setpoint_time_s=m._setpoint_time_s,
            item_seen=m._item_seen,
            land_descending=m._land_descending,
            mission=MissionSnapshot(
                items=_ref(mission.items),
                index=mission.index,
                items_reached=mission.items_reached,
                finished=mission.finished,
                hold_started_s=mission._hold_started_s,
            ),
            fence_zones=_ref(m.fence_zones),
            rally_points=list(m.rally_points),
            rtl_dest=m._rtl_dest,
            offboard_tick_s=m._offboard_tick_s,
            climb_alt_m=m._climb_alt_m,
            orbit=m._orbit,
        ),
        monitor=MonitorSnapshot(
            gcs_seen=mon.gcs_seen,
            last_gcs_s=mon.last_gcs_s,
            datalink_lost=mon.datalink_lost,
            outside_fence=mon.outside_fence,
            crashed=mon.crashed,
        ),
        controller=ControllerSnapshot(
            vel_integral=list(c._vi),
            rate_integral=list(c._ri),
            velocity_prev=c._v_prev,
            rates_prev=c._w_prev,
        ),
        estimator_rng=_estimator_rng(ap),
        sensor=_sensor_snapshot(sensor),
        behavior=_behavior_snapshot(ap, behavior_rng),
    )


def _estimator_rng(ap: Autopilot) -> RngState | None:
    # Reading a generator's state costs more than the rest of a snapshot: skip unused ones.
    est = ap.estimator
    noisy = est.position_noise_m > 0.0 or est.velocity_noise_m_s > 0.0
    return rng_state(est._rng) if noisy else None


def _sensor_snapshot(sensor: ConcentrationSensor) -> SensorSnapshot:
    # The sensor model keeps its lag as a last value and time, or as a short history of
    # samples; its noise from a running generator, or keyed by sample time (no state).
    rng = getattr(sensor, "_rng", None)
    noisy = getattr(sensor.config, "noise_std_g_m3", 0.0) > 0.0
    history = getattr(sensor, "_history", None)
    return SensorSnapshot(
        lagged_g_m3=getattr(sensor, "_lagged", None),
        last_time_s=getattr(sensor, "_last_time_s", None),
        rng=rng_state(rng) if noisy and isinstance(rng, np.random.Generator) else None,
        history=[(t, v) for t, v in history] if history is not None else None,
    )


_SKIP = (np.random.Generator,)  # a behaviour's generator is the context's: saved on its own


def _behavior_snapshot(ap: Autopilot, rng: np.random.Generator | None) -> BehaviorSnapshot | None:
    behavior = ap.behavior
    if behavior is None:
        return None
    own = getattr(behavior, "snapshot", None)
    try:
        if callable(own):
            data = own()
        else:
            data = {k: v for k, v in vars(behavior).items() if not isinstance(v, _SKIP)}
        raw = msgspec.msgpack.encode(data)
    except (TypeError, OverflowError) as exc:
        raise SnapshotError(
            f"{ap.vehicle_id}: the state of behaviour {type(behavior).__name__} cannot be "
            f"saved ({exc}); give it snapshot() and restore(data) methods"
        ) from None
    return BehaviorSnapshot(data=msgspec.Raw(raw), rng=rng_state(rng) if rng else None)


# ---------------------------------------------------------------------------- restore
def restore(
    ap: Autopilot,
    sensor: ConcentrationSensor,
    snap: VehicleSnapshot,
    behavior_rng: np.random.Generator | None = None,
) -> None:
    """Put ``snap`` into a freshly built autopilot (and sensor) of the same vehicle."""
    if snap.vehicle_id != ap.vehicle_id:
        raise SnapshotError(f"snapshot of {snap.vehicle_id} given to {ap.vehicle_id}")
    ap.now = snap.now_s
    ap.state = snap.state
    ap.est = snap.estimate
    ap._scenario_mission = _items_of(snap.scenario_mission)
    ap.behavior_error = snap.behavior_error
    ap.sensor_health = snap.sensor_health
    _restore_modes(ap, snap.modes)
    mon = ap.monitor
    mon.gcs_seen = snap.monitor.gcs_seen
    mon.last_gcs_s = snap.monitor.last_gcs_s
    mon.datalink_lost = snap.monitor.datalink_lost
    mon.outside_fence = snap.monitor.outside_fence
    mon.crashed = snap.monitor.crashed
    c = ap.controller
    c._vi = list(snap.controller.vel_integral)
    c._ri = list(snap.controller.rate_integral)
    c._v_prev = snap.controller.velocity_prev
    c._w_prev = snap.controller.rates_prev
    if snap.estimator_rng is not None:
        set_rng_state(ap.estimator._rng, snap.estimator_rng)
    _restore_sensor(sensor, snap.sensor)
    if snap.behavior is not None and ap.behavior is not None:
        _restore_behavior(ap.behavior, snap.behavior, behavior_rng)


def _restore_sensor(sensor: ConcentrationSensor, snap: SensorSnapshot) -> None:
    for name, value in (("_lagged", snap.lagged_g_m3), ("_last_time_s", snap.last_time_s)):
        if hasattr(sensor, name):
            setattr(sensor, name, value)
    history = getattr(sensor, "_history", None)
    if history is not None and snap.history is not None:
        history.clear()
        history.extend(snap.history)
    rng = getattr(sensor, "_rng", None)
    if snap.rng is not None and isinstance(rng, np.random.Generator):
        set_rng_state(rng, snap.rng)


def _restore_modes(ap: Autopilot, s: ModesSnapshot) -> None:
    m = ap.modes
    m.failsafe = s.failsafe
    m.mission.upload(_items_of(s.mission.items), m.origin)  # resolves the items again
    m.mission.index = s.mission.index
    m.mission.items_reached = s.mission.items_reached
    m.mission.finished = s.mission.finished
    m.mission._hold_started_s = s.mission.hold_started_s
    m.mode = s.mode
    m.home = s.home
    m.failsafe_reason = s.failsafe_reason
    m._target = s.target
    m._yaw = s.yaw_rad
    m._speed = s.speed_m_s
    m._touchdown_since = s.touchdown_since_s
    m._rtl_phase = RtlPhase(s.rtl_phase)
    m._rtl_alt = s.rtl_alt_m
    m._setpoint = s.setpoint
    m._setpoint_time_s = s.setpoint_time_s
    m._item_seen = s.item_seen
    m._land_descending = s.land_descending
    m.fence_zones = _zones_of(s.fence_zones)
    m.rally_points = list(s.rally_points)
    m._rtl_dest = s.rtl_dest
    m._offboard_tick_s = s.offboard_tick_s
    m._climb_alt_m = s.climb_alt_m
    m._orbit = s.orbit


def _restore_behavior(
    behavior: Any, snap: BehaviorSnapshot, rng: np.random.Generator | None
) -> None:
    data = msgspec.msgpack.decode(snap.data)
    own = getattr(behavior, "restore", None)
    if callable(own):
        own(data)
    else:
        for key, value in data.items():
            old = getattr(behavior, key, None)
            # msgpack has no tuples: give an attribute back the sequence type it had
            setattr(behavior, key, tuple(value) if isinstance(old, tuple) else value)
    if snap.rng is not None and rng is not None:
        set_rng_state(rng, snap.rng)


# ---------------------------------------------------------------------------- on disk
_HEAD = struct.Struct("<4sIIq")  # magic, CRC-32 of the payload, payload length, sequence
_MAGIC = b"APS1"


class SnapshotSlots:
    """The latest two records of one writer, in ``<path>.0`` and ``<path>.1`` in turn.

    A record is ``(sequence, payload)``; each write is one ``pwritev`` of a header (with a
    CRC-32 of the payload) and the payload at offset 0 of the older file. The file's pages
    survive a SIGKILL of the writer (they are the kernel's); a torn record fails its CRC and
    the other file still holds the previous one.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fds: list[int] = []
        self._seq = 0

    def paths(self) -> tuple[Path, Path]:
        return self.path.with_name(self.path.name + ".0"), self.path.with_name(
            self.path.name + ".1"
        )

    def open(self) -> None:
        """Open both files for writing (creating them); records already there stay readable
        until overwritten, and this writer's sequence continues after theirs."""
        try:
            self._fds = [os.open(p, os.O_RDWR | os.O_CREAT, 0o644) for p in self.paths()]
        except OSError as exc:
            raise SnapshotError(
                f"cannot write snapshot {self.path}: {exc.strerror or exc}"
            ) from None
        self._seq = max((seq for seq, _ in self.read_all()), default=0)

    def write(self, payload: bytes) -> None:
        self._seq += 1
        head = _HEAD.pack(_MAGIC, zlib.crc32(payload), len(payload), self._seq)
        os.pwritev(self._fds[self._seq % 2], [head, payload], 0)  # one call, no joined copy

    def read_all(self) -> list[tuple[int, bytes]]:
        """The valid records, newest first."""
        return sorted(self._records(), reverse=True)

    def _records(self) -> Iterator[tuple[int, bytes]]:
        for p in self.paths():
            try:
                data = p.read_bytes()
            except OSError:
                continue
            if len(data) < _HEAD.size:
                continue
            magic, crc, length, seq = _HEAD.unpack_from(data)
            payload = data[_HEAD.size : _HEAD.size + length]
            if magic == _MAGIC and len(payload) == length and zlib.crc32(payload) == crc:
                yield seq, payload

    def close(self) -> None:
        for fd in self._fds:
            os.close(fd)
        self._fds = []

    def remove(self) -> None:
        for p in self.paths():
            p.unlink(missing_ok=True)


_BLOB_HEAD = struct.Struct("<4sI16s")  # magic, payload length, blake2b-128 of the payload
_BLOB_MAGIC = b"APB1"


class BlobLog:
    """The encoded lists of :data:`BLOBS` (missions, fence zones) on disk: each appended once,
    in one write, before a snapshot that refers to it is written (:meth:`flush`). A record
    whose digest does not match (a write cut short by a kill) ends the log: it is cut off
    there when the log is opened again."""

    def __init__(self, path: Path, blobs: Blobs = BLOBS) -> None:
        self.path = path
        self.blobs = blobs
        self._fd = -1
        self._written: set[str] = set()
        self._next = 0  # blobs.order[:_next] are written (or were already on disk)

    def open(self) -> None:
        """Give the lists already in the log to :data:`BLOBS`, then append after them."""
        end = 0
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            data = b""
        except OSError as exc:
            raise SnapshotError(f"cannot read {self.path}: {exc.strerror or exc}") from None
        for key, payload, after in _blob_records(data):
            self.blobs.add(payload)
            self._written.add(key)
            end = after
        try:
            self._fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            os.ftruncate(self._fd, end)  # a torn last record
            os.lseek(self._fd, end, os.SEEK_SET)
        except OSError as exc:
            raise SnapshotError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        self._next = 0

    def flush(self) -> None:
        """Append the lists first seen since the last call (nothing, almost every tick)."""
        order = self.blobs.order
        if self._next == len(order) or self._fd < 0:
            return
        for key in order[self._next :]:
            if key in self._written:
                continue
            payload = bytes(self.blobs.by_key[key])
            head = _BLOB_HEAD.pack(_BLOB_MAGIC, len(payload), bytes.fromhex(key))
            os.writev(self._fd, [head, payload])
            self._written.add(key)
        self._next = len(order)

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = -1


def _blob_records(data: bytes) -> Iterator[tuple[str, bytes, int]]:
    """(key, payload, offset after it) of the valid records at the start of ``data``."""
    at = 0
    while at + _BLOB_HEAD.size <= len(data):
        magic, length, digest = _BLOB_HEAD.unpack_from(data, at)
        start = at + _BLOB_HEAD.size
        payload = data[start : start + length]
        if magic != _BLOB_MAGIC or len(payload) != length:
            return
        if hashlib.blake2b(payload, digest_size=16).digest() != digest:
            return
        at = start + length
        yield digest.hex(), payload, at


# ---------------------------------------------------------------------------- a process
class PendingSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    """The sensor tick whose plume values a process awaits (they come in a later tick;
    ``by_physics``: that tick waited for the plume's sample, ``SimTick.plume_queried``)."""

    tick: int
    sim_time_s: float
    heads: list[tuple[str, Vec3]]  # every vehicle's id and position in that tick
    by_physics: bool


class ProcessSnapshot(msgspec.Struct, frozen=True, kw_only=True):
    """An autopilot process after handling tick ``tick`` (and any command since)."""

    format: str = FORMAT
    node: str
    tick: int  # -1: before the first tick
    vehicles: list[VehicleSnapshot]
    commands: list[bytes]  # one per vehicle, empty: the process answers with ``batch``
    batch: bytes = b""  # the process's ActuatorBatch for ``tick`` (resent if it repeats)
    status_times_s: list[float]
    pending: PendingSnapshot | None


_process_decoder = msgspec.msgpack.Decoder(ProcessSnapshot)


def missing_lists(snap: ProcessSnapshot) -> list[str]:
    """The mission and fence lists ``snap`` refers to that :data:`BLOBS` does not hold."""
    keys = [
        key
        for v in snap.vehicles
        for key in (v.scenario_mission, v.modes.mission.items, v.modes.fence_zones)
    ]
    return sorted({k for k in keys if k not in BLOBS.by_key})


def decode_process(payload: bytes) -> ProcessSnapshot:
    try:
        snap = _process_decoder.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise SnapshotError(f"not an autopilot snapshot: {exc}") from None
    if snap.format != FORMAT:
        raise SnapshotError(f"snapshot format {snap.format!r}, not {FORMAT}")
    return snap
