"""Typed, versioned messages for every payload of the key space (docs/bus.md).

Every message is a ``msgspec.Struct`` tagged with ``schema = "<name>/v<version>"``; decoding a
payload with another version fails with a typed error. Floats are bounded (which also rejects
NaN and inf) unless a field says otherwise. Encode and decode with :mod:`swarmbus.codec`.
"""

from __future__ import annotations

import enum
from typing import Annotated, Literal

import msgspec

SCHEMA_VERSION = 1

# Bounded floats: the bounds reject NaN and +-inf as well as absurd magnitudes.
Finite = Annotated[float, msgspec.Meta(ge=-1e9, le=1e9)]
NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Positive = Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
Unit = Annotated[float, msgspec.Meta(ge=0.0, le=1.0)]
Latitude = Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
Longitude = Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
Altitude = Annotated[float, msgspec.Meta(ge=-1e5, le=1e6)]
SimTime = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Tick = Annotated[int, msgspec.Meta(ge=0, le=2**62)]
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]
Text = Annotated[str, msgspec.Meta(max_length=1000)]
Vec3 = tuple[Finite, Finite, Finite]
Quat = tuple[Finite, Finite, Finite, Finite]

MAX_BATCH_POINTS = 100_000
MAX_ROTORS = 16
MAX_MISSION_ITEMS = 1000
MAX_BATCH_COMMANDS = 1024  # vehicles one autopilot process may serve (ActuatorBatch)


def _tag(name: str) -> str:
    return f"{name}/v{SCHEMA_VERSION}"


class Message(msgspec.Struct, frozen=True, kw_only=True, tag_field="schema"):
    """Base of all bus messages."""


# --------------------------------------------------------------------------- sim plane
class SpeedMode(enum.StrEnum):
    LOCKSTEP = "lockstep"
    REALTIME = "realtime"
    STEPPED = "stepped"  # one client grants ticks (StepRequest on clock/step)


class Clock(Message, frozen=True, kw_only=True, tag=_tag("clock")):
    """``sim/clock``: the physics' view of time."""

    tick: Tick
    sim_time_s: SimTime
    mode: SpeedMode
    speed_factor: Positive
    real_time_factor: NonNegative
    participants: list[Name] = []


class VehicleState(Message, frozen=True, kw_only=True, tag=_tag("vehicle_state")):
    """``vehicle/<id>/state`` and an element of ``sim/tick``: ground truth from physics.

    ENU world frame (x east, y north, z up) in metres, origin at the scenario origin;
    ``attitude_xyzw`` rotates body (FLU: x forward, y left, z up) to world.
    """

    vehicle_id: Name
    tick: Tick
    sim_time_s: SimTime
    position_enu_m: Vec3
    velocity_enu_m_s: Vec3
    attitude_xyzw: Quat
    body_rates_rad_s: Vec3
    lat_deg: Latitude
    lon_deg: Longitude
    alt_m: Altitude
    on_ground: bool
    crashed: bool = False
    motors_enabled: bool = True


class PlumeSample(msgspec.Struct, frozen=True, kw_only=True):
    """The plume's values at the positions of every state of tick ``tick``, in that order;
    ``None`` when the plume service did not answer (readings are then unavailable)."""

    tick: Tick
    values_g_m3: list[NonNegative] | None


class SimTick(Message, frozen=True, kw_only=True, tag=_tag("sim_tick")):
    """``sim/tick``: all vehicle states of tick k in one message (the lockstep's go signal).

    ``plume_queried``: a sensor tick that a plume service takes part in: the physics waits for
    the service's :class:`FieldSample` of this tick's positions and carries its values in
    ``plume_values`` of the next tick. False: no plume service takes part (the readings of
    this tick are unavailable).
    """

    tick: Tick
    sim_time_s: SimTime
    control_dt_s: Positive
    states: list[VehicleState]
    plume_queried: bool = False
    plume_values: PlumeSample | None = None


class ActuatorCommand(Message, frozen=True, kw_only=True, tag=_tag("actuators")):
    """One vehicle's normalised rotor commands (0..1) for tick ``tick``: an entry of an
    ``ActuatorBatch`` (the one actuator route, ``autopilot/<node>/actuators``)."""

    vehicle_id: Name
    tick: Tick
    rotor_commands: Annotated[list[Unit], msgspec.Meta(max_length=MAX_ROTORS)]


class ActuatorBatch(Message, frozen=True, kw_only=True, tag=_tag("actuator_batch")):
    """``autopilot/<node>/actuators``: the commands of every vehicle one autopilot process
    serves for tick ``tick``, in one message (one put per process per tick instead of one per
    vehicle). Each entry counts as that vehicle's ``ActuatorCommand``; the physics drops an
    entry whose ``tick`` is not the batch's."""

    tick: Tick
    commands: Annotated[list[ActuatorCommand], msgspec.Meta(max_length=MAX_BATCH_COMMANDS)]


# --------------------------------------------------------------------------- vehicle status
class FlightMode(enum.StrEnum):
    DISARMED = "disarmed"
    ARMED = "armed"  # armed on the ground, idle
    TAKEOFF = "takeoff"
    HOLD = "hold"
    MISSION = "mission"
    LAND = "land"
    RTL = "rtl"
    OFFBOARD = "offboard"
    ORBIT = "orbit"  # circling a point (MAVLink DO_ORBIT)
    POSITION = "position"  # PX4's position mode, flown from a ground station's sticks
    FOLLOW = "follow"  # PX4's follow-me: setpoints computed from a moving target


class VehicleStatus(Message, frozen=True, kw_only=True, tag=_tag("vehicle_status")):
    """``vehicle/<id>/status``: the autopilot's view of its vehicle."""

    vehicle_id: Name
    sim_time_s: SimTime
    mode: FlightMode
    armed: bool
    landed: bool
    crashed: bool = False
    mission_index: Annotated[int, msgspec.Meta(ge=-1, le=MAX_MISSION_ITEMS)] = -1
    mission_count: Annotated[int, msgspec.Meta(ge=0, le=MAX_MISSION_ITEMS)] = 0
    mission_items_reached: Annotated[int, msgspec.Meta(ge=0, le=MAX_MISSION_ITEMS)] = 0
    mission_finished: bool = False
    home_enu_m: Vec3 = (0.0, 0.0, 0.0)
    failsafe: Text = ""
    health: Text = "ok"


class PeerReading(msgspec.Struct, frozen=True, kw_only=True):
    vehicle_id: Name
    position_enu_m: Vec3
    true_g_m3: NonNegative


class ConcentrationReading(Message, frozen=True, kw_only=True, tag=_tag("concentration")):
    """``vehicle/<id>/concentration``: the sensor's reading at the vehicle's own position.

    ``available`` is false when the plume service did not answer: then ``reported_g_m3`` and
    ``true_g_m3`` are ``None``, never a silent 0. A sensor with a named ``gas`` also reports
    ``reported_ppm`` (the same value in ppm of that gas); a metal-oxide sensor also reports its
    raw ``resistance_ohm`` (``reported_g_m3`` is then the calibrated concentration).
    """

    vehicle_id: Name
    sim_time_s: SimTime
    position_enu_m: Vec3
    available: bool
    reported_g_m3: NonNegative | None
    true_g_m3: NonNegative | None
    peers: list[PeerReading] = []
    gas: Name | None = None
    reported_ppm: NonNegative | None = None
    resistance_ohm: NonNegative | None = None


# --------------------------------------------------------------------------- commands
class MissionFrame(enum.StrEnum):
    """The frame of a mission item's x, y, z: the world's ENU metres, or geodetic."""

    ENU = "enu"
    GLOBAL = "global"  # x = latitude deg, y = longitude deg, z = altitude AMSL m


class MissionCommand(enum.StrEnum):
    """What a mission item does (MAVLink NAV_WAYPOINT, NAV_TAKEOFF, NAV_LAND, NAV_RTL)."""

    WAYPOINT = "waypoint"
    TAKEOFF = "takeoff"
    LAND = "land"
    RTL = "rtl"


class MissionItem(msgspec.Struct, frozen=True, kw_only=True):
    """One mission item. ``frame = enu``: x, y, z metres in the world frame (z above origin);
    ``frame = global``: x latitude (deg), y longitude (deg), z altitude AMSL (m)."""

    command: Annotated[
        MissionCommand,
        msgspec.Meta(description="What the item does: waypoint, takeoff, land or rtl."),
    ] = MissionCommand.WAYPOINT
    x: Annotated[Finite, msgspec.Meta(description="enu: east, m; global: latitude, degrees.")]
    y: Annotated[Finite, msgspec.Meta(description="enu: north, m; global: longitude, degrees.")]
    z: Annotated[
        Finite,
        msgspec.Meta(description="enu: height above the origin, m; global: altitude AMSL, m."),
    ]
    frame: Annotated[
        MissionFrame,
        msgspec.Meta(
            description="enu: the world frame in metres; global: latitude, longitude, altitude."
        ),
    ] = MissionFrame.ENU
    acceptance_radius_m: Annotated[
        float,
        msgspec.Meta(gt=0.0, le=1000.0, description="The item is reached within this distance, m."),
    ] = 1.0
    hold_s: Annotated[
        float,
        msgspec.Meta(ge=0.0, le=3600.0, description="Seconds to hold at the item once reached."),
    ] = 0.0
    speed_m_s: Annotated[
        float,
        msgspec.Meta(
            ge=0.0, le=100.0, description="Speed towards the item, m/s; 0: the vehicle's default."
        ),
    ] = 0.0
    yaw_deg: Annotated[
        Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)] | None,
        msgspec.Meta(description="Heading at the item, degrees; unset: the vehicle's choice."),
    ] = None


class Arm(Message, frozen=True, kw_only=True, tag=_tag("cmd.arm")):
    pass


class Disarm(Message, frozen=True, kw_only=True, tag=_tag("cmd.disarm")):
    force: bool = False  # MAVLink's 21196: disarm even in the air


class Takeoff(Message, frozen=True, kw_only=True, tag=_tag("cmd.takeoff")):
    altitude_m: Annotated[float, msgspec.Meta(gt=0.0, le=10000.0)]  # above home


class Land(Message, frozen=True, kw_only=True, tag=_tag("cmd.land")):
    pass


class ReturnToLaunch(Message, frozen=True, kw_only=True, tag=_tag("cmd.rtl")):
    pass


class Hold(Message, frozen=True, kw_only=True, tag=_tag("cmd.hold")):
    pass


class Goto(Message, frozen=True, kw_only=True, tag=_tag("cmd.goto")):
    position_enu_m: Vec3
    yaw_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)] | None = None
    speed_m_s: Annotated[float, msgspec.Meta(ge=0.0, le=100.0)] = 0.0


class SetMode(Message, frozen=True, kw_only=True, tag=_tag("cmd.set_mode")):
    mode: FlightMode


class MissionUpload(Message, frozen=True, kw_only=True, tag=_tag("cmd.mission_upload")):
    items: Annotated[list[MissionItem], msgspec.Meta(max_length=MAX_MISSION_ITEMS)]


class MissionStart(Message, frozen=True, kw_only=True, tag=_tag("cmd.mission_start")):
    start_index: Annotated[int, msgspec.Meta(ge=0, le=MAX_MISSION_ITEMS)] = 0


class MissionPause(Message, frozen=True, kw_only=True, tag=_tag("cmd.mission_pause")):
    pass


class MissionClear(Message, frozen=True, kw_only=True, tag=_tag("cmd.mission_clear")):
    pass


class MissionDownload(Message, frozen=True, kw_only=True, tag=_tag("cmd.mission_download")):
    pass


class Setpoint(Message, frozen=True, kw_only=True, tag=_tag("cmd.setpoint")):
    """Offboard setpoint (world ENU, body FLU), the kinds PX4 accepts:

    - a position, a velocity or an acceleration, or a combination (with a position, velocity
      and acceleration are feed-forward), with a yaw or a yaw rate;
    - an attitude (``attitude_xyzw``, body → world) or body rates (``body_rates_rad_s``), each
      with a collective ``thrust`` (fraction of the vehicle's maximum).
    """

    position_enu_m: Vec3 | None = None
    velocity_enu_m_s: Vec3 | None = None
    yaw_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)] | None = None
    acceleration_enu_m_s2: Vec3 | None = None
    yaw_rate_deg_s: Annotated[float, msgspec.Meta(ge=-3600.0, le=3600.0)] | None = None
    attitude_xyzw: Quat | None = None
    body_rates_rad_s: Vec3 | None = None
    thrust: Unit | None = None


class GcsHeartbeat(Message, frozen=True, kw_only=True, tag=_tag("cmd.gcs_heartbeat")):
    """The ground-control link is alive (feeds the data-link-loss failsafe)."""

    source: Text = "gcs"


class SetParam(Message, frozen=True, kw_only=True, tag=_tag("cmd.set_param")):
    name: Annotated[str, msgspec.Meta(pattern=r"^[A-Z0-9_]{1,16}$")]
    value: Finite


class GetParams(Message, frozen=True, kw_only=True, tag=_tag("cmd.get_params")):
    pass


class OrbitYaw(enum.IntEnum):
    """Where the nose points while orbiting (MAVLink ORBIT_YAW_BEHAVIOUR)."""

    CENTRE = 0
    HOLD_INITIAL = 1
    UNCONTROLLED = 2
    TANGENT = 3


class Orbit(Message, frozen=True, kw_only=True, tag=_tag("cmd.orbit")):
    """Circle ``center_enu_m`` (its z is the altitude) at ``radius_m``; ``speed_m_s`` > 0
    clockwise seen from above, < 0 counter-clockwise (PX4's convention)."""

    center_enu_m: Vec3
    radius_m: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)]
    speed_m_s: Annotated[float, msgspec.Meta(ge=-50.0, le=50.0)]
    yaw: OrbitYaw = OrbitYaw.CENTRE


# PX4's codes for the failsafe-action parameters that SetParam / GetParams carry as numbers
NAV_DLL_ACT_CODES = {"none": 0, "hold": 1, "rtl": 2, "land": 3}  # PX4 NAV_DLL_ACT
COM_OBL_ACT_CODES = {"land": 0, "hold": 1, "rtl": 2}  # PX4 COM_OBL_ACT (no terminate)
ACTION_CODES_OF_PARAM = {"NAV_DLL_ACT": NAV_DLL_ACT_CODES, "COM_OBL_ACT": COM_OBL_ACT_CODES}


# --------------------------------------------------------------------------- geofence, rally
MAX_FENCE_VERTICES = 1000


class FenceZone(msgspec.Struct, frozen=True, kw_only=True):
    """A geofence zone in the world ENU frame: a polygon (``polygon_enu_m``, ≥ 3 vertices) or
    a circle (``center_enu_m`` and ``radius_m``). Inclusion: the vehicle stays inside (inside
    at least one, when there are several); exclusion: it stays out."""

    inclusion: bool = True
    polygon_enu_m: (
        Annotated[
            list[tuple[Finite, Finite]],
            msgspec.Meta(min_length=3, max_length=MAX_FENCE_VERTICES),
        ]
        | None
    ) = None
    center_enu_m: tuple[Finite, Finite] | None = None
    radius_m: Positive | None = None


class GeofenceUpload(Message, frozen=True, kw_only=True, tag=_tag("cmd.geofence_upload")):
    """Replace the uploaded geofence zones (empty: none; the GF_* limits stay)."""

    zones: Annotated[list[FenceZone], msgspec.Meta(max_length=MAX_MISSION_ITEMS)]


class RallyUpload(Message, frozen=True, kw_only=True, tag=_tag("cmd.rally_upload")):
    """Replace the rally points (ENU m): RTL goes to the closest of home and these."""

    points_enu_m: Annotated[list[Vec3], msgspec.Meta(max_length=MAX_MISSION_ITEMS)]


Command = (
    Arm
    | Disarm
    | Takeoff
    | Land
    | ReturnToLaunch
    | Hold
    | Goto
    | SetMode
    | MissionUpload
    | MissionStart
    | MissionPause
    | MissionClear
    | MissionDownload
    | Setpoint
    | GcsHeartbeat
    | SetParam
    | GetParams
    | GeofenceUpload
    | RallyUpload
    | Orbit
)


class RejectCode(enum.StrEnum):
    NONE = ""
    DENIED = "denied"  # valid but refused in the current state
    INVALID = "invalid"  # malformed or out-of-range argument
    UNSUPPORTED = "unsupported"
    FAILED = "failed"


class CommandReply(Message, frozen=True, kw_only=True, tag=_tag("cmd_reply")):
    """Reply of ``vehicle/<id>/cmd``: accepted, or rejected with a code and a reason."""

    vehicle_id: Name
    accepted: bool
    code: RejectCode = RejectCode.NONE
    reason: Text = ""
    mission: list[MissionItem] | None = None  # MissionDownload
    params: dict[str, float] | None = None  # GetParams / SetParam


# --------------------------------------------------------------------------- plume
class PlumeQuery(Message, frozen=True, kw_only=True, tag=_tag("plume_query")):
    """``plume/concentration`` request: a batch of points (ENU m), optional sim time."""

    points_enu_m: Annotated[list[Vec3], msgspec.Meta(max_length=MAX_BATCH_POINTS)]
    sim_time_s: SimTime | None = None


class PlumeValues(Message, frozen=True, kw_only=True, tag=_tag("plume_values")):
    values_g_m3: list[NonNegative]
    sim_time_s: SimTime | None = None


class FieldSample(Message, frozen=True, kw_only=True, tag=_tag("field_sample")):
    """``field/sample``: the plume service's answer to sensor tick ``tick`` of ``sim/tick``: the
    concentration at the position of every state of that tick, in that order, at its sim time
    (a lockstep participant's answer, like an autopilot's actuators); ``values_g_m3`` None
    when the service could not compute them (the readings are then unavailable)."""

    tick: Tick
    sim_time_s: SimTime
    values_g_m3: Annotated[list[NonNegative], msgspec.Meta(max_length=MAX_BATCH_POINTS)] | None


class PlumeSource(msgspec.Struct, frozen=True, kw_only=True):
    x_m: Finite
    y_m: Finite
    release_rate_g_s: Positive
    release_height_m: NonNegative


class PlumeInfo(Message, frozen=True, kw_only=True, tag=_tag("plume_info")):
    model: Text
    stability: Text
    coefficients: Text
    wind_speed_m_s: Positive
    wind_from_deg: Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]
    mixing_height_m: Positive | None
    sources: list[PlumeSource]
    wind_model: Text = "steady"
    time_dependent: bool = False  # filament, puff: the value depends on sim_time_s
    # One line per σ fit used outside its published range (the fits hold from about 100 m).
    sigma_validity: list[Text] = []


class PlumeInfoQuery(Message, frozen=True, kw_only=True, tag=_tag("plume_info_query")):
    pass


class PlumeMeshQuery(Message, frozen=True, kw_only=True, tag=_tag("plume_mesh_query")):
    level_g_m3: Positive
    resolution_m: Annotated[float, msgspec.Meta(ge=0.01, le=100.0)] = 0.5
    bounds_min_m: Vec3 | None = None
    bounds_max_m: Vec3 | None = None


class PlumeMesh(Message, frozen=True, kw_only=True, tag=_tag("plume_mesh")):
    """Isosurface: ``vertices`` little-endian float32 (V,3), ``faces`` little-endian int32 (F,3)."""

    level_g_m3: Positive
    vertices_f32: bytes
    faces_i32: bytes


class ErrorReply(Message, frozen=True, kw_only=True, tag=_tag("error")):
    """Error reply of any queryable: which field was wrong and why."""

    field: Text
    reason: Text


# --------------------------------------------------------------------------- stepped clock
MAX_STEP_TICKS = 2**31


class StepRequest(Message, frozen=True, kw_only=True, tag=_tag("step_request")):
    """``clock/step`` query: advance a stepped world by ``ticks`` ticks. ``client`` names the
    clock holder (its liveliness token ``node/<client>/health``); a world is stepped by one
    client at a time."""

    client: Name
    ticks: Annotated[int, msgspec.Meta(ge=1, le=MAX_STEP_TICKS)]


class StepReply(Message, frozen=True, kw_only=True, tag=_tag("step_reply")):
    """Answer to a ``StepRequest`` once tick ``tick`` is published and every participant
    answered it: the world is paused there until the next request."""

    tick: Tick
    sim_time_s: SimTime


# --------------------------------------------------------------------------- dynamic plume
class PlumeState(Message, frozen=True, kw_only=True, tag=_tag("plume_state")):
    """``field/state``: the filaments or puffs of a time-dependent plume at ``sim_time_s``.

    ``centres_f32``: little-endian float32 (P, 3) ENU m; ``radii_f32``: float32 (P,) m (a
    filament's R, a puff's σy). Published a few times per sim second for viewers and recorders.
    """

    sim_time_s: SimTime
    model: Text
    count: Annotated[int, msgspec.Meta(ge=0, le=2**31)]
    centres_f32: bytes
    radii_f32: bytes


class AnemometerReading(Message, frozen=True, kw_only=True, tag=_tag("anemometer")):
    """``vehicle/<id>/wind``: the vehicle's anemometer, the scenario's wind at its position
    with the instrument's own seeded noise (ENU m/s), and the true value."""

    vehicle_id: Name
    sim_time_s: SimTime
    position_enu_m: Vec3
    wind_enu_m_s: Vec3
    true_wind_enu_m_s: Vec3


# --------------------------------------------------------------------------- presence
class NodeState(enum.StrEnum):
    UP = "up"
    READY = "ready"
    STOPPING = "stopping"
    ERROR = "error"  # alive but failing at its job (``detail`` says why), e.g. a full disk


class NodeHealth(Message, frozen=True, kw_only=True, tag=_tag("node_health")):
    """``node/<name>/health``: published on change and periodically by every process."""

    name: Name
    role: Name
    state: NodeState
    version: Text
    pid: Annotated[int, msgspec.Meta(ge=0)]
    host: Text
    sim_time_s: SimTime | None = None
    detail: Text = ""
    scenario: Text = ""  # the node's swarmbus.scenario.scenario_hash ("": not said)
    vehicles: Annotated[list[Name], msgspec.Meta(max_length=MAX_BATCH_COMMANDS)] = []
    """The vehicles the process serves (an autopilot's)."""


# --------------------------------------------------------------------------- restarts
class RestartNotice(Message, frozen=True, kw_only=True, tag=_tag("restart_notice")):
    """``node/<name>/restart``: the launcher's word on a process of its run that ended.

    ``restarting`` true: it will be started again in ``delay_s`` (its backoff); false: it is
    gone for good. ``vehicles`` are the vehicles the process served (an autopilot's), so the
    physics can hold the lockstep for them instead of dropping them.
    """

    node: Name
    role: Name
    restarting: bool
    returncode: int
    delay_s: NonNegative = 0.0
    restarts: Annotated[int, msgspec.Meta(ge=0)] = 0  # restarts before this one
    vehicles: Annotated[list[Name], msgspec.Meta(max_length=MAX_BATCH_COMMANDS)] = []


ALL_MESSAGES: tuple[type[Message], ...] = (
    Clock,
    VehicleState,
    SimTick,
    ActuatorCommand,
    ActuatorBatch,
    VehicleStatus,
    ConcentrationReading,
    Arm,
    Disarm,
    Takeoff,
    Land,
    ReturnToLaunch,
    Hold,
    Goto,
    SetMode,
    MissionUpload,
    MissionStart,
    MissionPause,
    MissionClear,
    MissionDownload,
    Setpoint,
    GcsHeartbeat,
    SetParam,
    GetParams,
    GeofenceUpload,
    RallyUpload,
    Orbit,
    CommandReply,
    PlumeQuery,
    PlumeValues,
    PlumeInfo,
    PlumeInfoQuery,
    PlumeMeshQuery,
    PlumeMesh,
    ErrorReply,
    NodeHealth,
    StepRequest,
    StepReply,
    RestartNotice,
    PlumeState,
    FieldSample,
    AnemometerReading,
)

__all__ = [m.__name__ for m in ALL_MESSAGES] + [
    "Command",
    "FenceZone",
    "FlightMode",
    "OrbitYaw",
    "MissionCommand",
    "MissionFrame",
    "MissionItem",
    "NodeState",
    "PeerReading",
    "PlumeSource",
    "RejectCode",
    "SpeedMode",
    "Literal",
]
