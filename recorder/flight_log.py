"""A recorded flight as arrays: per-vehicle track, readings and status, plus the plume it flew in.

One pass over the recording; only the messages a report needs are decoded. Vehicle states come
from ``vehicle/<id>/state``; a vehicle that has none there is taken from ``sim/tick``.
"""

from __future__ import annotations

import logging
import math
from collections import defaultdict
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import msgspec
import numpy as np
import numpy.typing as npt
from tqdm import tqdm

from recorder.reader import Recorded, Recording, RecordingError
from recorder.schema import (
    EVENTS_TOPIC,
    GAPS_TOPIC,
    RecorderEvent,
    SegmentGap,
    gap_from_json,
)
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import (
    ConcentrationReading,
    PlumeInfo,
    SimTick,
    VehicleState,
    VehicleStatus,
)
from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]


@dataclass
class _Columns:
    """One vehicle's time series, a column of equal length per field, in time order."""

    columns: dict[str, FloatArray]

    @property
    def t(self) -> FloatArray:
        return self.columns["sim_time_s"]

    def __len__(self) -> int:
        return len(self.t)


@dataclass
class Track(_Columns):
    """Ground truth of one vehicle, in time order (sim time)."""


@dataclass
class Readings(_Columns):
    """Sensor readings of one vehicle; unavailable values are NaN."""


@dataclass
class FlightLog:
    world: str
    tracks: dict[str, Track] = field(default_factory=dict)
    readings: dict[str, Readings] = field(default_factory=dict)
    modes: dict[str, list[tuple[float, str]]] = field(default_factory=dict)
    plume_info: PlumeInfo | None = None
    scenario: Scenario | None = None
    events: list[RecorderEvent] = field(default_factory=list)
    message_count: int = 0
    truncated: bool = False
    segments: list[str] = field(default_factory=list)  # file names, in order
    gaps: list[SegmentGap] = field(default_factory=list)  # not recorded between segments

    @property
    def vehicles(self) -> list[str]:
        return sorted(set(self.tracks) | set(self.readings))


TRACK_FIELDS = (
    "sim_time_s",
    "tick",
    "x_m",
    "y_m",
    "z_m",
    "vx_m_s",
    "vy_m_s",
    "vz_m_s",
    "lat_deg",
    "lon_deg",
    "alt_m",
    "on_ground",
)
READING_FIELDS = (
    "sim_time_s",
    "x_m",
    "y_m",
    "z_m",
    "available",
    "reported_g_m3",
    "true_g_m3",
    "reported_ppm",
    "resistance_ohm",
)


def _state_row(s: VehicleState) -> tuple[float, ...]:
    return (
        s.sim_time_s,
        float(s.tick),
        *s.position_enu_m,
        *s.velocity_enu_m_s,
        s.lat_deg,
        s.lon_deg,
        s.alt_m,
        float(s.on_ground),
    )


def _reading_row(r: ConcentrationReading) -> tuple[float, ...]:
    def value(v: float | None) -> float:
        return math.nan if v is None or not r.available else v

    return (
        r.sim_time_s,
        *r.position_enu_m,
        float(r.available),
        value(r.reported_g_m3),
        value(r.true_g_m3),
        value(r.reported_ppm),
        value(r.resistance_ohm),
    )


def _columns(rows: list[tuple[float, ...]], names: tuple[str, ...]) -> dict[str, FloatArray]:
    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(names))
    order = np.argsort(table[:, 0], kind="stable")
    return {name: table[order, i] for i, name in enumerate(names)}


class _Collector:
    def __init__(self, keys: Keys) -> None:
        self.keys = keys
        self.states: dict[str, list[tuple[float, ...]]] = defaultdict(list)
        self.tick_states: dict[str, list[tuple[float, ...]]] = defaultdict(list)
        self.readings: dict[str, list[tuple[float, ...]]] = defaultdict(list)
        self.modes: dict[str, list[tuple[float, str]]] = defaultdict(list)
        self.plume_info: PlumeInfo | None = None
        self.events: list[RecorderEvent] = []
        self.gaps: list[SegmentGap] = []
        leaf: dict[str, Callable[[Recorded], None]] = {
            "state": self._state,
            "concentration": self._reading,
            "status": self._status,
        }
        self._vehicle_leaf = leaf
        # The recorder's own channels (not bus messages), then the bus keys read whole.
        self._recorder_topics: dict[str, Callable[[Recorded], None]] = {
            EVENTS_TOPIC: self._event,
            GAPS_TOPIC: self._gap,
        }
        self._bus_topics: dict[str, Callable[[Recorded], None]] = {
            keys.tick(): self._tick,
            keys.plume_info(): self._plume_info,
        }

    def add(self, rec: Recorded) -> None:
        own = self._recorder_topics.get(rec.topic)
        if own is not None:
            own(rec)
            return
        if not rec.is_bus_message:
            return
        handler = self._bus_topics.get(rec.topic)
        if handler is None and self.keys.relative(rec.topic).startswith("vehicle/"):
            handler = self._vehicle_leaf.get(rec.topic.rsplit("/", 1)[-1])
        if handler is not None:
            handler(rec)

    def _event(self, rec: Recorded) -> None:
        event = rec.event()
        if event is not None:
            self.events.append(event)

    def _gap(self, rec: Recorded) -> None:
        self.gaps.append(gap_from_json(rec.data))

    def _tick(self, rec: Recorded) -> None:
        msg = rec.message()
        if isinstance(msg, SimTick):
            for s in msg.states:
                self.tick_states[s.vehicle_id].append(_state_row(s))

    def _plume_info(self, rec: Recorded) -> None:
        msg = rec.message()
        if isinstance(msg, PlumeInfo):
            self.plume_info = msg

    def _state(self, rec: Recorded) -> None:
        msg = rec.message()
        if isinstance(msg, VehicleState):
            self.states[msg.vehicle_id].append(_state_row(msg))

    def _reading(self, rec: Recorded) -> None:
        msg = rec.message()
        if isinstance(msg, ConcentrationReading):
            self.readings[msg.vehicle_id].append(_reading_row(msg))

    def _status(self, rec: Recorded) -> None:
        msg = rec.message()
        if isinstance(msg, VehicleStatus):
            modes = self.modes[msg.vehicle_id]
            if not modes or modes[-1][1] != msg.mode:
                modes.append((msg.sim_time_s, str(msg.mode)))


def scenario_of(recording: Recording) -> Scenario | None:
    text = recording.metadata.get("plumeswarm", {}).get("scenario")
    if not text:
        return None
    try:
        return msgspec.json.decode(text, type=Scenario)
    except msgspec.MsgspecError as exc:
        log.warning("the recorded scenario cannot be read (%s); reporting without it", exc)
        return None


def load_flight(recording: Recording, progress: bool | None = None) -> FlightLog:
    """Read ``recording`` into a :class:`FlightLog` (``progress``: None = only on a terminal)."""
    world = recording.metadata.get("plumeswarm", {}).get("world", "default")
    try:
        keys = Keys(world)
    except KeyNameError as exc:
        raise RecordingError(f"{recording.path}: bad world name in metadata: {exc}") from None
    collector = _Collector(keys)
    count = 0
    messages: Iterable[Recorded] = recording.messages()
    bar = tqdm(
        messages,
        total=recording.message_count,
        unit="msg",
        desc="reading",
        disable=None if progress is None else not progress,
        leave=False,
    )
    for rec in bar:
        collector.add(rec)
        count += 1
    flight = FlightLog(
        world=world,
        plume_info=collector.plume_info,
        scenario=scenario_of(recording),
        events=collector.events,
        message_count=count,
        truncated=recording.truncated,
        segments=[p.name for p in recording.segments],
        gaps=collector.gaps,
    )
    for vid in sorted(set(collector.states) | set(collector.tick_states)):
        rows = collector.states.get(vid) or collector.tick_states[vid]
        flight.tracks[vid] = Track(_columns(rows, TRACK_FIELDS))
    for vid, rows in sorted(collector.readings.items()):
        flight.readings[vid] = Readings(_columns(rows, READING_FIELDS))
    flight.modes = dict(collector.modes)
    return flight
