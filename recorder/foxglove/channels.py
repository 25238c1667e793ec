"""The Foxglove channels of a run: their topics, rates and schemas, the encoding of a message,
and the small pieces every entity is made of (stamps, colours, poses). See docs/recording.md,
"Foxglove"."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import msgspec
from foxglove import messages as fm

WORLD_FRAME = "world"
TF_TOPIC = "/tf"
VEHICLES_TOPIC = "/scene/vehicles"
TRAILS_TOPIC = "/scene/trails"
READINGS_TOPIC = "/scene/readings"
PLUME_TOPIC = "/scene/plume"
PLUME_STATE_TOPIC = "/scene/plume_state"
LOCATION_PREFIX = "/location/"
CONCENTRATION_PREFIX = "/concentration/"

# Rates, in simulation time (a channel gets at most one message per period).
TF_PERIOD_S = 0.05  # 20 Hz: every vehicle's pose in one FrameTransforms
LOCATION_PERIOD_S = 0.2  # 5 Hz per vehicle
READINGS_PERIOD_S = 0.1  # 10 Hz: the newest reading of every vehicle
SERIES_PERIOD_S = 0.05  # up to 20 Hz per vehicle (the sensor's own rate when lower)
TRAILS_PERIOD_S = 2.0  # 0.5 Hz: every trail, whole (a seek shows the newest message only)
TRAIL_POINT_PERIOD_S = 1.0  # a trail point per vehicle per sim second ...
TRAIL_MAX_POINTS = 300  # ... the last 5 minutes of it (a full 32-vehicle update: 9600 points)
PLUME_STATE_PERIOD_S = 0.5  # at most 2 Hz: the plume's default field/state period
PLUME_STATE_MAX_SPHERES = 1000  # more filaments or puffs are thinned evenly to this many
PLUME_STATE_MIN_DIAMETER_M = 0.2  # a fresh filament (R0 ≈ 3 cm) would be a pixel at 50 m
PLUME_STATE_ALPHA = 0.5

VEHICLE_SCALE = 4.0  # drawn size (as the meshcat viewer): a 0.5 m quadcopter vanishes at 60 m
NO_READING_RGB = 0x9E9E9E
DEFAULT_VEHICLE_TYPE = "iris"
RESTART_S = 1.0  # sim time this far back is a new start (a replay, a restored checkpoint)
_EPS_S = 1e-9


def location_topic(vehicle_id: str) -> str:
    return LOCATION_PREFIX + vehicle_id


def concentration_topic(vehicle_id: str) -> str:
    return CONCENTRATION_PREFIX + vehicle_id


class ConcentrationSample(msgspec.Struct, frozen=True, kw_only=True):
    """One point of a vehicle's concentration series (``/concentration/<id>``, JSON).
    ``reported_g_m3`` / ``true_g_m3`` are null when the plume did not answer."""

    vehicle_id: str
    sim_time_s: float
    available: bool
    reported_g_m3: float | None
    true_g_m3: float | None
    x_m: float
    y_m: float
    z_m: float


FoxgloveMessage = fm.FrameTransforms | fm.SceneUpdate | fm.LocationFix | ConcentrationSample


class Out(NamedTuple):
    """One message for a Foxglove channel; ``log_time_ns`` is the anchored simulation time."""

    topic: str
    message: FoxgloveMessage
    log_time_ns: int


class ChannelSchema(NamedTuple):
    name: str
    encoding: str  # "protobuf" or "jsonschema"
    data: bytes
    message_encoding: str  # "protobuf" or "json"


_schemas: dict[type, ChannelSchema] = {}


def channel_schema(type_: type) -> ChannelSchema:
    """The schema a Foxglove channel carrying ``type_`` declares (the SDK's own for its
    well-known messages)."""
    cs = _schemas.get(type_)
    if cs is None:
        if type_ is ConcentrationSample:
            data = msgspec.json.encode(msgspec.json.schema(ConcentrationSample))
            cs = ChannelSchema("plumeswarm.ConcentrationSample", "jsonschema", data, "json")
        else:
            schema = type_.get_schema()  # type: ignore[attr-defined]
            cs = ChannelSchema(schema.name, schema.encoding, bytes(schema.data), "protobuf")
        _schemas[type_] = cs
    return cs


_json = msgspec.json.Encoder()


def encode(message: FoxgloveMessage) -> bytes:
    """``message`` in its channel's message encoding."""
    if isinstance(message, ConcentrationSample):
        return _json.encode(message)
    return bytes(message.encode())


# --------------------------------------------------------------------------- small builders
def stamp(ns: int) -> fm.Timestamp:
    return fm.Timestamp(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)


def colour(rgb: int, alpha: float = 1.0) -> fm.Color:
    return fm.Color(
        r=((rgb >> 16) & 0xFF) / 255, g=((rgb >> 8) & 0xFF) / 255, b=(rgb & 0xFF) / 255, a=alpha
    )


def pose(x: float = 0.0, y: float = 0.0, z: float = 0.0) -> fm.Pose:
    return fm.Pose(
        position=fm.Vector3(x=x, y=y, z=z), orientation=fm.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
    )


def heading_rad(xyzw: Sequence[float]) -> float:
    """Heading clockwise from north of a body (FLU) whose attitude in ENU is ``xyzw``."""
    x, y, z, w = xyzw
    yaw_from_east = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    return (math.pi / 2.0 - yaw_from_east) % (2.0 * math.pi)


class Every:
    """Due once per ``period_s`` of simulation time; time going backwards (a replay, a restart
    from a checkpoint) starts over."""

    def __init__(self, period_s: float) -> None:
        self.period_s = period_s
        self.last_s: float | None = None

    def due(self, t_s: float) -> bool:
        if self.last_s is not None and self.last_s <= t_s < self.last_s + self.period_s - _EPS_S:
            return False
        self.last_s = t_s
        return True
