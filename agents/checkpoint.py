"""Checkpoints of an autopilot process's state (:func:`capture`, :func:`restore`), so a restarted
autopilot carries on with the same bits; :mod:`agents.checkpoint_store` keeps them (the two-slot
files, the by-reference mission and fence lists). See docs/agents.md ("Restarts: the autopilot
resumes where it was").
"""

from __future__ import annotations

import logging
import typing
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import msgspec
import numpy as np

from agents.checkpoint_store import BLOBS
from agents.checkpoint_store import CheckpointError as CheckpointError  # raised here too
from agents.control import Estimate
from agents.mode_table import RtlPhase
from swarmbus.messages import FenceZone, FlightMode, MissionItem, Orbit, Setpoint, VehicleState
from swarmbus.scenario import Failsafe

if TYPE_CHECKING:
    from agents.autopilot import Autopilot
    from agents.sensor import ConcentrationSensor

log = logging.getLogger(__name__)

FORMAT = "autopilot_checkpoint/v4"
Vec3 = tuple[float, float, float]
S = TypeVar("S", bound=msgspec.Struct)


class RngState(msgspec.Struct, frozen=True, array_like=True):
    """A numpy PCG64 generator's state (the 128-bit words as decimal strings)."""

    state: str
    inc: str
    has_uint32: int
    uinteger: int


def rng_state(rng: np.random.Generator) -> RngState:
    st = rng.bit_generator.state
    if st["bit_generator"] != "PCG64":
        raise CheckpointError(f"cannot save a {st['bit_generator']} generator (PCG64 only)")
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


class ControllerCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    vel_integral: list[float]
    rate_integral: list[float]
    velocity_prev: Vec3 | None
    rates_prev: Vec3 | None


class MissionCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    items: str  # list[MissionItem], by reference (BLOBS)
    index: int
    items_reached: int
    finished: bool
    hold_started_s: float | None


class ModesCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    mode: FlightMode
    failsafe: Failsafe
    home: Vec3
    failsafe_reason: str
    target: Vec3
    yaw_rad: float
    speed_m_s: float
    touchdown_since_s: float | None
    rtl_phase: str
    rtl_altitude_m: float
    setpoint: Setpoint | None
    setpoint_time_s: float
    item_seen: int
    land_descending: bool
    mission: MissionCheckpoint
    fence_zones: str  # list[FenceZone], by reference (BLOBS)
    rally_points: list[Vec3]
    rtl_dest: Vec3
    offboard_tick_s: float
    climb_altitude_m: float | None
    orbit: Orbit | None


class MonitorCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    gcs_seen: bool
    last_gcs_s: float
    datalink_lost: bool
    outside_fence: bool
    crashed: bool


class SensorCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    """The sensor's state, whichever of these its model keeps (the others are None)."""

    lagged_g_m3: float | None
    last_time_s: float | None
    rng: RngState | None  # a sensor that draws its noise from a running generator
    history: list[tuple[float, float]] | None = None  # (sim time, lag state) of recent samples


class BehaviorCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    data: msgspec.Raw  # the behaviour's checkpoint() or its attributes, msgpack
    rng: RngState | None


class VehicleCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    vehicle_id: str
    now_s: float
    state: VehicleState | None
    estimate: Estimate | None
    scenario_mission: str  # list[MissionItem], by reference (BLOBS)
    behavior_error: str
    sensor_health: str
    modes: ModesCheckpoint
    monitor: MonitorCheckpoint
    controller: ControllerCheckpoint
    estimator_rng: RngState | None  # None: no noise, the generator is never drawn from
    sensor: SensorCheckpoint
    behavior: BehaviorCheckpoint | None


# ---------------------------------------------------------------------------- field tables
class _Part(Generic[S]):
    """How one part of the autopilot is saved: each field of its checkpoint struct ``kind`` (but
    the ``special`` ones, saved otherwise) holds the attribute of the same name, or the one
    ``renamed`` gives. List fields are copied both ways, so that a checkpoint never shares a
    list with the running autopilot.

    A checkpoint is taken every tick, so ``save`` is compiled once from the struct's fields and
    the table (identifiers only) into one keyword call, as dataclasses compile their
    ``__init__``: a loop over the fields made a capture two to three times as slow (≈ 6 →
    15–30 µs a vehicle on a loaded machine); compiled, it is within ≈ 1 µs of spelled-out
    keywords."""

    def __init__(
        self, kind: type[S], renamed: dict[str, str] | None = None, special: tuple[str, ...] = ()
    ) -> None:
        names = renamed or {}
        fields = [f for f in msgspec.structs.fields(kind) if f.name not in special]
        self.lists = frozenset(f.name for f in fields if typing.get_origin(f.type) is list)
        self.attributes = {f.name: names.get(f.name, f.name) for f in fields}
        values = ", ".join(
            f"{f}=list(part.{a})" if f in self.lists else f"{f}=part.{a}"
            for f, a in self.attributes.items()
        )
        self.save: Callable[..., S] = eval(
            f"lambda part, **special: kind({values}, **special)", {"kind": kind, "list": list}
        )

    def put_back(self, part: Any, snap: S) -> None:
        for name, attribute in self.attributes.items():
            value = getattr(snap, name)
            setattr(part, attribute, list(value) if name in self.lists else value)


_MONITOR = _Part(MonitorCheckpoint)
_CONTROLLER = _Part(
    ControllerCheckpoint,
    {
        "vel_integral": "_vi",
        "rate_integral": "_ri",
        "velocity_prev": "_v_prev",
        "rates_prev": "_w_prev",
    },
)
_MISSION = _Part(MissionCheckpoint, {"hold_started_s": "_hold_started_s"}, special=("items",))
_MODES = _Part(
    ModesCheckpoint,
    {
        "target": "_target",
        "yaw_rad": "_yaw",
        "speed_m_s": "_speed",
        "touchdown_since_s": "_touchdown_since",
        "rtl_altitude_m": "_rtl_alt",
        "setpoint": "_setpoint",
        "setpoint_time_s": "_setpoint_time_s",
        "item_seen": "_item_seen",
        "land_descending": "_land_descending",
        "rtl_dest": "_rtl_dest",
        "offboard_tick_s": "_offboard_tick_s",
        "climb_altitude_m": "_climb_altitude_m",
        "orbit": "_orbit",
    },
    special=("mission", "rtl_phase", "fence_zones"),
)


# ---------------------------------------------------------------------------- capture
_NO_ITEMS = msgspec.Raw(msgspec.msgpack.encode([]))
_NO_ITEMS_KEY = BLOBS.add(_NO_ITEMS)
_items_decoder = msgspec.msgpack.Decoder(list[MissionItem])
_zones_decoder = msgspec.msgpack.Decoder(list[FenceZone])


def _items_raw(items: list[MissionItem]) -> msgspec.Raw:
    """``items`` encoded, once per list (an empty list: one shared encoding)."""
    return _NO_ITEMS if not items else BLOBS.encoded(items)[0]


def _ref(items: list[Any]) -> str:
    return _NO_ITEMS_KEY if not items else BLOBS.encoded(items)[1]


def _decoded(decoder: msgspec.msgpack.Decoder[list[Any]], key: str, what: str) -> list[Any]:
    try:
        return decoder.decode(BLOBS.get(key, what))
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise CheckpointError(f"{what}: {exc}") from None


def _items_of(key: str) -> list[MissionItem]:
    return _decoded(_items_decoder, key, "mission items")


def _zones_of(key: str) -> list[FenceZone]:
    return _decoded(_zones_decoder, key, "fence zones")


def capture(
    ap: Autopilot,
    sensor: ConcentrationSensor,
    behavior_rng: np.random.Generator | None = None,
) -> VehicleCheckpoint:
    """Everything of ``ap`` (and its sensor) that influences its future, as of now."""
    m = ap.modes
    return VehicleCheckpoint(
        vehicle_id=ap.vehicle_id,
        now_s=ap.now,
        state=ap.state,
        estimate=ap.est,
        scenario_mission=_ref(ap._scenario_mission),
        behavior_error=ap.behavior_error,
        sensor_health=ap.sensor_health,
        modes=_MODES.save(
            m,
            rtl_phase=m._rtl_phase.value,
            mission=_MISSION.save(m.mission, items=_ref(m.mission.items)),
            fence_zones=_ref(m.fence_zones),
        ),
        monitor=_MONITOR.save(ap.monitor),
        controller=_CONTROLLER.save(ap.controller),
        estimator_rng=_estimator_rng(ap),
        sensor=_sensor_checkpoint(sensor),
        behavior=_behavior_checkpoint(ap, behavior_rng),
    )


def _estimator_rng(ap: Autopilot) -> RngState | None:
    # Reading a generator's state costs more than the rest of a checkpoint: skip unused ones.
    est = ap.estimator
    noisy = est.position_noise_m > 0.0 or est.velocity_noise_m_s > 0.0
    return rng_state(est._rng) if noisy else None


def _sensor_checkpoint(sensor: ConcentrationSensor) -> SensorCheckpoint:
    # The sensor model keeps its lag as a last value and time, or as a short history of
    # samples; its noise from a running generator, or keyed by sample time (no state).
    rng = getattr(sensor, "_rng", None)
    noisy = getattr(sensor.config, "noise_std_g_m3", 0.0) > 0.0
    history = getattr(sensor, "_history", None)
    return SensorCheckpoint(
        lagged_g_m3=getattr(sensor, "_lagged", None),
        last_time_s=getattr(sensor, "_last_time_s", None),
        rng=rng_state(rng) if noisy and isinstance(rng, np.random.Generator) else None,
        history=[(t, v) for t, v in history] if history is not None else None,
    )


_SKIP = (np.random.Generator,)  # a behaviour's generator is the context's: saved on its own


def _behavior_checkpoint(
    ap: Autopilot, rng: np.random.Generator | None
) -> BehaviorCheckpoint | None:
    behavior = ap.behavior
    if behavior is None:
        return None
    own = getattr(behavior, "checkpoint", None)
    if callable(old := getattr(behavior, "snapshot", None)):  # its own, under the former name
        own = old
        _deprecated_snapshot(type(behavior))
    try:
        if callable(own):
            data = own()
        else:
            data = {k: v for k, v in vars(behavior).items() if not isinstance(v, _SKIP)}
        raw = msgspec.msgpack.encode(data)
    except (TypeError, OverflowError) as exc:
        raise CheckpointError(
            f"{ap.vehicle_id}: the state of behaviour {type(behavior).__name__} cannot be "
            f"saved ({exc}); give it checkpoint() and restore(data) methods"
        ) from None
    return BehaviorCheckpoint(data=msgspec.Raw(raw), rng=rng_state(rng) if rng else None)


_WARNED: set[type] = set()


def _deprecated_snapshot(kind: type) -> None:
    """A behaviour with the former ``snapshot()``: one line per class."""
    if kind not in _WARNED:
        _WARNED.add(kind)
        log.warning(
            "behaviour %s: snapshot() is deprecated, name it checkpoint(); it is called as "
            "checkpoint() until the next release",
            kind.__name__,
        )


# ---------------------------------------------------------------------------- restore
def restore(
    ap: Autopilot,
    sensor: ConcentrationSensor,
    snap: VehicleCheckpoint,
    behavior_rng: np.random.Generator | None = None,
) -> None:
    """Put ``snap`` into a freshly built autopilot (and sensor) of the same vehicle."""
    if snap.vehicle_id != ap.vehicle_id:
        raise CheckpointError(f"checkpoint of {snap.vehicle_id} given to {ap.vehicle_id}")
    ap.now = snap.now_s
    ap.state = snap.state
    ap.est = snap.estimate
    ap._scenario_mission = _items_of(snap.scenario_mission)
    ap.behavior_error = snap.behavior_error
    ap.sensor_health = snap.sensor_health
    _restore_modes(ap, snap.modes)
    _MONITOR.put_back(ap.monitor, snap.monitor)
    _CONTROLLER.put_back(ap.controller, snap.controller)
    if snap.estimator_rng is not None:
        set_rng_state(ap.estimator._rng, snap.estimator_rng)
    _restore_sensor(sensor, snap.sensor)
    if snap.behavior is not None and ap.behavior is not None:
        _restore_behavior(ap.behavior, snap.behavior, behavior_rng)


def _restore_sensor(sensor: ConcentrationSensor, snap: SensorCheckpoint) -> None:
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


def _restore_modes(ap: Autopilot, s: ModesCheckpoint) -> None:
    m = ap.modes
    m.mission.upload(_items_of(s.mission.items), m.origin)  # resolves the items again
    _MISSION.put_back(m.mission, s.mission)
    _MODES.put_back(m, s)
    m._rtl_phase = RtlPhase(s.rtl_phase)
    m.fence_zones = _zones_of(s.fence_zones)


def _restore_behavior(
    behavior: Any, snap: BehaviorCheckpoint, rng: np.random.Generator | None
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


# ---------------------------------------------------------------------------- a process
class PendingCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    """The sensor tick whose plume values a process awaits (they come in a later tick;
    ``by_physics``: that tick waited for the plume's sample, ``SimTick.plume_queried``)."""

    tick: int
    sim_time_s: float
    heads: list[tuple[str, Vec3]]  # every vehicle's id and position in that tick
    by_physics: bool


class HandledCommand(msgspec.Struct, frozen=True):
    """A command a process handled after answering tick ``after_tick`` (``swarmbus.codec``
    encoding): a replay from an earlier checkpoint handles it again there."""

    after_tick: int
    vehicle_id: str
    command: bytes


class ProcessCheckpoint(msgspec.Struct, frozen=True, kw_only=True):
    """An autopilot process after handling tick ``tick`` (and any command since)."""

    format: str = FORMAT
    node: str
    tick: int  # -1: before the first tick
    vehicles: list[VehicleCheckpoint]
    commands: list[bytes]  # one per vehicle, empty: the process answers with ``batch``
    batch: bytes = b""  # the process's ActuatorBatch for ``tick`` (resent if it repeats)
    status_times_s: list[float]
    pending: PendingCheckpoint | None
    # The radio (agents.peer_link.PeerLink.snapshot: messages in flight, what each vehicle
    # has heard, the counts, the messages of ``tick`` not yet sent) and the states of ``tick``
    # it sends them with; empty when the link is off.
    link: bytes = b""
    link_states: list[VehicleState] = []
    # The commands handled since the oldest checkpoint kept for a rewind (agents.resume)
    handled: list[HandledCommand] = []


_process_decoder = msgspec.msgpack.Decoder(ProcessCheckpoint)


def missing_lists(snap: ProcessCheckpoint) -> list[str]:
    """The mission and fence lists ``snap`` refers to that :data:`BLOBS` does not hold."""
    keys = [
        key
        for v in snap.vehicles
        for key in (v.scenario_mission, v.modes.mission.items, v.modes.fence_zones)
    ]
    return sorted({k for k in keys if k not in BLOBS.by_key})


def decode_process(payload: bytes) -> ProcessCheckpoint:
    try:
        snap = _process_decoder.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as exc:
        raise CheckpointError(f"not an autopilot checkpoint: {exc}") from None
    if snap.format != FORMAT:
        raise CheckpointError(f"checkpoint format {snap.format!r}, not {FORMAT}")
    return snap
