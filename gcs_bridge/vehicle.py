"""What the gateway knows and remembers of one vehicle: identity, latest bus data, home,
parameters, the mission as MAVLink sees it, and the events its status changes imply.
"""

from __future__ import annotations

import functools
import logging
from dataclasses import dataclass, field
from typing import Generic, Protocol, TypeVar

import msgspec
from packaging.version import InvalidVersion, Version

from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.frames import Vec3, enu_to_geodetic
from gcs_bridge.mission import Converted, Place, Uploader, WireItem, seq_of_bus_index, wire_of_items
from gcs_bridge.modes import (
    base_mode_of,
    custom_mode_of,
    mav_type_of,
    px4_mode_of,
    system_status_of,
)
from gcs_bridge.params import ParamTable
from gcs_bridge.telemetry import View
from plume_atmosphere.wind import WindModel
from swarmbus.codec import decode_or_none
from swarmbus.messages import (
    ConcentrationReading,
    FlightMode,
    MissionItem,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import package_version
from swarmbus.scenario import Origin, Scenario
from swarmbus.vehicle_types import load_vehicle_type

PX4_VERSION = (1 << 24) | (14 << 16) | (0 << 8) | 255  # "v1.14.0 release", as PX4 encodes it
CAPABILITIES = (
    mavlink.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mavlink.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mavlink.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
log = logging.getLogger(__name__)

UID_BASE = 0x504C554D45000000  # "PLUME" + sysid
UID2_LEN = 18
# MISSION_CURRENT.mission_mode (not named in pymavlink 2.4.50): 1 in mission mode, 2 suspended.
MISSION_MODE_ACTIVE = 1
MISSION_MODE_SUSPENDED = 2
ARMING_SETTLE_S = 5.0  # wall: how long an accepted Arm stands in for a status saying armed


@functools.cache
def vendor_custom_version() -> tuple[int, ...]:
    """AUTOPILOT_VERSION.flight_custom_version: plumeswarm's major.minor.patch in its first
    three bytes, patch first (where MAVSDK reads a vendor version), the git-hash bytes zero."""
    try:
        release = Version(package_version()).release
    except InvalidVersion:
        release = ()
    major, minor, patch = (*release, 0, 0, 0)[:3]
    return (patch & 0xFF, minor & 0xFF, major & 0xFF, 0, 0, 0, 0, 0)


Buffer = bytes | msgspec.Raw


class _OfVehicle(Protocol):
    @property
    def vehicle_id(self) -> str: ...


M = TypeVar("M", bound=_OfVehicle)


class Latest(Generic[M]):
    """The newest valid message of one kind about one vehicle. A newer payload is kept encoded
    and decoded only when read (most are replaced before anyone reads them: the bus brings
    one per control tick, telemetry wants a few per second); an invalid one, or one about
    another vehicle, is logged and leaves the previous message."""

    def __init__(self, kind: type[M], vehicle_id: str) -> None:
        self._kind = kind
        self._vehicle_id = vehicle_id
        self._what = f"{kind.__name__} of {vehicle_id}"
        self._value: M | None = None
        self._raw: Buffer | None = None

    def feed(self, raw: Buffer) -> None:
        self._raw = raw

    def set(self, value: M | None) -> None:
        self._value, self._raw = value, None

    def get(self) -> M | None:
        raw = self._raw
        if raw is not None:
            self._raw = None
            value = decode_or_none(memoryview(raw), self._kind, self._what, log)
            if value is not None and value.vehicle_id == self._vehicle_id:
                self._value = value
        return self._value


@dataclass
class MissionCurrent:
    seq: int
    total: int
    state: int
    mode: int


@dataclass(frozen=True)
class ArmIntent:
    """A mode selected while disarmed; arming then flies it (PX4 semantics, which QGC's
    takeoff and start-mission flows rely on: NAV_TAKEOFF or SET_MODE first, then ARM)."""

    mode: FlightMode
    altitude_m: float = 0.0


@dataclass
class StatusEvents:
    """What a new status means for MAVLink: a heartbeat now, items reached, a new current."""

    heartbeat: bool = False
    reached_seqs: list[int] = field(default_factory=list)
    mission_current: bool = False
    home_changed: bool = False


class Vehicle:
    def __init__(
        self,
        scenario: Scenario,
        vehicle_id: str,
        index: int,
        wind_enu: Vec3,
        air: WindModel | None = None,
    ) -> None:
        """``wind_enu``: the scenario's steady wind (a multirotor's VFR_HUD airspeed); ``air``:
        the physics' wind model, a fixed wing's airspeed is against it where it flies."""
        cfg = scenario.vehicle(vehicle_id)
        vtype = load_vehicle_type(cfg.type)
        self.id = vehicle_id
        self.state_label = f"state of {vehicle_id}"  # how a refused message is logged
        self.status_label = f"status of {vehicle_id}"
        self.index = index
        sysid = scenario.sysid_of(vehicle_id)
        if sysid is None:
            raise ValueError(f"vehicle {vehicle_id!r} has no MAVLink sysid")
        self.sysid = sysid
        self.mav_type = mav_type_of(vtype.kind, len(vtype.rotors))
        self.origin: Origin = scenario.world.origin
        self.wind_enu = wind_enu
        self._air = air if vtype.fixed_wing is not None else None
        self.params = ParamTable(scenario.failsafe_for(vehicle_id), vtype)
        self.params_synced = False
        self._state = Latest(VehicleState, vehicle_id)
        self.status: VehicleStatus | None = None
        self._reading = Latest(ConcentrationReading, vehicle_id)
        self.spawn_enu: Vec3 = cfg.spawn_enu_m
        self.uploader = Uploader()
        self.mission: Converted | None = None  # as MAVLink last saw it (upload or download)
        self.download: list[WireItem] = []
        self.plans: dict[int, list[WireItem]] = {}  # fence and rally items as accepted
        self._home_geo: Vec3 | None = None
        self.intent: ArmIntent | None = None
        self.arming_since_s: float | None = None  # wall: an Arm sent, no armed status yet
        self.last_status_wall_s = -1e9
        self.last_gcs_heartbeat_s = -1e9  # wall
        self.last_gcs_heartbeat_sim_s = -1e9
        self._reached = 0
        self._current: MissionCurrent | None = None

    # -- the latest bus data -------------------------------------------------------
    @property
    def state(self) -> VehicleState | None:
        """The newest valid state (one fed undecoded is decoded here, when first needed)."""
        return self._state.get()

    @state.setter
    def state(self, state: VehicleState | None) -> None:
        self._state.set(state)

    def feed_state(self, raw: Buffer) -> None:
        """A newer state, still encoded: decoded only if someone reads :attr:`state`."""
        self._state.feed(raw)

    @property
    def reading(self) -> ConcentrationReading | None:
        """The newest valid reading (decoded when first needed, like :attr:`state`)."""
        return self._reading.get()

    @reading.setter
    def reading(self, reading: ConcentrationReading | None) -> None:
        self._reading.set(reading)

    def feed_reading(self, raw: Buffer) -> None:
        self._reading.feed(raw)

    # -- identity ---------------------------------------------------------------
    def heartbeat(self) -> Msg:
        """Armed: the autopilot's real mode. Disarmed: the mode selected for arming, if any."""
        custom = custom_mode_of(self.status)
        if self.intent is not None and not self.armed:
            custom = px4_mode_of(self.intent.mode).custom_mode
        return mavlink.MAVLink_heartbeat_message(
            self.mav_type,
            mavlink.MAV_AUTOPILOT_PX4,
            base_mode_of(self.status),
            custom,
            system_status_of(self.status),
            3,
        )

    @property
    def armed(self) -> bool:
        return self.status is not None and self.status.armed

    def arming(self, now: float) -> bool:
        """An Arm is on its way or was accepted, and no status saying armed has arrived yet.

        The autopilot publishes its status before it replies, but the gateway may handle the
        reply first (they reach it by different paths), so a GCS that sends its next command
        as soon as the ARM's ACK arrives must not find the vehicle "still disarmed"."""
        return self.arming_since_s is not None and now - self.arming_since_s < ARMING_SETTLE_S

    def armable(self) -> str | None:
        """None if the vehicle could arm now, else why not."""
        st = self.status
        if st is None:
            return "no status from the autopilot yet"
        if st.armed:
            return "already armed"
        if st.crashed:
            return "crashed"
        if not st.landed:
            return "not on the ground"
        if st.health != "ok":
            return f"unhealthy: {st.health}"
        return None

    def autopilot_version(self) -> Msg:
        """PX4's version (what ground stations key PX4 features on), plumeswarm's own as the
        vendor version, and the sysid's identity in both uid fields: MAVSDK's hardware_uid is
        uid2, and all-zero uid2s would make every vehicle of a swarm look the same."""
        zeros = [0] * 8
        uid = UID_BASE | self.sysid
        uid2 = list(uid.to_bytes(8, "big")) + [0] * (UID2_LEN - 8)
        return mavlink.MAVLink_autopilot_version_message(
            CAPABILITIES,
            PX4_VERSION,
            0,
            0,
            0,
            vendor_custom_version(),
            zeros,
            zeros,
            0,
            0,
            uid,
            uid2,
        )

    # -- home -------------------------------------------------------------------
    @property
    def home_enu(self) -> Vec3 | None:
        if self.status is not None:
            return self.status.home_enu_m
        return None

    def home_place(self) -> Place:
        """Home for mission conversion (before the autopilot reports: its spawn point)."""
        enu = self.home_enu if self.home_enu is not None else self.spawn_enu
        lat, lon, alt = enu_to_geodetic(enu, self.origin)
        return Place(lat, lon, alt, self.origin)

    @property
    def home_amsl_m(self) -> float | None:
        return self.home_place().alt_amsl_m if self.home_enu is not None else None

    def wind_at(self, state: VehicleState | None) -> Vec3:
        """The wind a VFR_HUD airspeed is against: a fixed wing's, the physics' wind model at
        its position and sim time (what its wings and pitot feel); a multirotor's, the
        scenario's steady wind."""
        if self._air is None or state is None:
            return self.wind_enu
        uniform = self._air.uniform_at(state.sim_time_s)
        if uniform is not None:
            return (float(uniform[0]), float(uniform[1]), float(uniform[2]))
        w = self._air.velocity([state.position_enu_m], state.sim_time_s)[0]
        return (float(w[0]), float(w[1]), float(w[2]))

    def view(self) -> View:
        home = self.home_enu
        if home is not None and self._home_geo is None:
            self._home_geo = enu_to_geodetic(home, self.origin)
        state = self.state
        return View(
            state,
            self.status,
            self.reading,
            self._home_geo,
            home,
            self.wind_at(state),
            self.spawn_enu,
        )

    # -- mission bookkeeping ----------------------------------------------------
    def _mapping_valid(self) -> bool:
        return (
            self.mission is not None
            and self.status is not None
            and len(self.mission.items) == self.status.mission_count
        )

    def seq_of(self, bus_index: int) -> int:
        if self._mapping_valid() and self.mission is not None:
            return seq_of_bus_index(self.mission.seqs, bus_index)
        return bus_index

    def seqs(self) -> list[int]:
        if self._mapping_valid() and self.mission is not None:
            return self.mission.seqs
        count = self.status.mission_count if self.status is not None else 0
        return list(range(count))

    def mission_total(self) -> int:
        if self._mapping_valid() and self.mission is not None:
            return len(self.mission.wire)
        return self.status.mission_count if self.status is not None else 0

    def mission_current(self) -> MissionCurrent:
        st = self.status
        total = self.mission_total()
        if st is None or st.mission_count == 0:
            return MissionCurrent(0, total, mavlink.MISSION_STATE_NO_MISSION, 0)
        index = min(max(st.mission_index, 0), st.mission_count - 1)
        in_mission = st.mode == FlightMode.MISSION
        if st.mission_finished:
            state = mavlink.MISSION_STATE_COMPLETE
        elif in_mission:
            state = mavlink.MISSION_STATE_ACTIVE
        elif st.mission_items_reached > 0:
            state = mavlink.MISSION_STATE_PAUSED
        else:
            state = mavlink.MISSION_STATE_NOT_STARTED
        mode = MISSION_MODE_ACTIVE if in_mission else MISSION_MODE_SUSPENDED
        return MissionCurrent(self.seq_of(index), total, int(state), mode)

    def mission_current_msg(self) -> Msg:
        mc = self.mission_current()
        self._current = mc
        return mavlink.MAVLink_mission_current_message(mc.seq, mc.total, mc.state, mc.mode)

    def remember_upload(self, converted: Converted) -> None:
        self.mission = converted
        self._reached = 0

    def wire_for_download(self, items: list[MissionItem]) -> list[WireItem]:
        """The autopilot's mission as MAVLink items: verbatim if it is what MAVLink uploaded."""
        if self.mission is not None and self.mission.items == items:
            return self.mission.wire
        wire = wire_of_items(items, self.home_place())
        self.mission = Converted(items=list(items), seqs=list(range(len(items))), wire=wire)
        return wire

    # -- status -------------------------------------------------------------------
    def update_status(self, status: VehicleStatus, wall_s: float) -> StatusEvents:
        old = self.status
        self.status = status
        self.last_status_wall_s = wall_s
        ev = StatusEvents()
        if status.armed or status.crashed:
            self.intent = None  # from now on the heartbeat shows the real mode
            self.arming_since_s = None
        if old is None or (old.mode, old.armed, old.crashed, bool(old.failsafe)) != (
            status.mode,
            status.armed,
            status.crashed,
            bool(status.failsafe),
        ):
            ev.heartbeat = True
        if old is None or old.home_enu_m != status.home_enu_m:
            ev.home_changed = True
            self._home_geo = None
        reached = status.mission_items_reached
        if old is None or reached < self._reached:
            self._reached = reached  # first sight, or a new mission: nothing to announce
        elif reached > self._reached:
            ev.reached_seqs = [self.seq_of(k) for k in range(self._reached, reached)]
            self._reached = reached
        if self._current is None or self.mission_current() != self._current:
            ev.mission_current = True
        return ev
