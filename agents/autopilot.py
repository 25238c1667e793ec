"""One vehicle's autopilot without any I/O: estimate → failsafes → modes → control → mixer.

The node (:mod:`agents.autopilot_node`) feeds it the physics' state every tick and the
commands from the bus; tests fly it against simple dynamics. Commands map to handlers through a
dispatch table; every refusal carries a :class:`~swarmbus.messages.RejectCode` and a reason.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Sequence
from typing import Any

import msgspec

from agents.behavior import Behavior
from agents.control import Controller, Estimate
from agents.estimator import Estimator
from agents.failsafe import FailsafeMonitor
from agents.fixed_wing import IDLE, FixedWingPilot
from agents.mixer import Mixer
from agents.mode_table import AIRBORNE, Refusal, denied, invalid
from agents.modes import FlightModes
from plume_atmosphere.wind import wind_from_scenario
from swarmbus.messages import (
    ACTION_CODES_OF_PARAM,
    Arm,
    CommandReply,
    ConcentrationReading,
    Disarm,
    FlightMode,
    GcsHeartbeat,
    GeofenceUpload,
    GetParams,
    Goto,
    Hold,
    Land,
    MissionClear,
    MissionDownload,
    MissionItem,
    MissionPause,
    MissionStart,
    MissionUpload,
    Orbit,
    RallyUpload,
    RejectCode,
    ReturnToLaunch,
    SetMode,
    SetParam,
    Setpoint,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.scenario import Scenario
from swarmbus.vehicle_types import FixedWingParams, load_vehicle_type

log = logging.getLogger(__name__)

STATE_LOST = "vehicle state lost"
IDLE_COMMAND = 0.15  # rotor command while armed on the ground (props spinning)

# PX4-style parameter names → failsafe field, with the enum encodings PX4 uses
# (ACTION_CODES_OF_PARAM).
_PARAMS: dict[str, str] = {
    "NAV_DLL_ACT": "datalink_loss_action",
    "COM_DL_LOSS_T": "datalink_timeout_s",
    "COM_OBL_ACT": "offboard_loss_action",
    "COM_OF_LOSS_T": "offboard_timeout_s",
    "RTL_RETURN_ALT": "rtl_altitude_m",
    "GF_MAX_VER_DIST": "geofence_max_altitude_m",
    "GF_MAX_HOR_DIST": "geofence_max_distance_m",
    "MIS_TAKEOFF_ALT": "takeoff_altitude_m",
}
# a fixed wing's PX4 parameters (swarmbus.vehicle_types.FixedWingParams), by their PX4 names
_FIXED_WING_PARAMS = frozenset(msgspec.to_builtins(FixedWingParams()))


class Autopilot:
    def __init__(
        self,
        scenario: Scenario,
        vehicle_id: str,
        estimator: Estimator | None = None,
        behavior: Behavior | None = None,
    ) -> None:
        vehicle = scenario.vehicle(vehicle_id)
        self.vehicle_id = vehicle_id
        self.vehicle_type = load_vehicle_type(vehicle.type)
        self.control_dt_s = 1.0 / scenario.time.control_hz
        self.controller = Controller(self.vehicle_type, self.control_dt_s)
        self.modes = FlightModes(scenario.failsafe_for(vehicle_id), scenario.world.origin)
        fw = self.vehicle_type.fixed_wing
        # the vehicle kind selects the controller: the multirotor cascade and mixer, or the
        # fixed-wing pilot (agents/fixed_wing.py) on the same modes
        self.pilot = (
            FixedWingPilot(fw, self.control_dt_s, self.modes, wind_from_scenario(scenario))
            if fw is not None
            else None
        )
        self.mixer = Mixer(self.vehicle_type) if fw is None else None
        self.monitor = FailsafeMonitor(self.modes)
        self.estimator = estimator or Estimator()
        self.behavior = behavior
        self.modes.has_behavior = behavior is not None
        self.behavior_error = ""
        self.sensor_health = ""  # set by the node: why readings are unavailable
        self.state: VehicleState | None = None
        self.est: Estimate | None = None
        self.now = 0.0
        # the scenario's mission is uploaded with the first state, when home is known
        self._scenario_mission = list(vehicle.mission)
        self._spawn = vehicle.spawn_enu_m
        if self.mixer is not None:
            self._zero = [0.0] * self.mixer.rotor_count
            self._idle = [IDLE_COMMAND] * self.mixer.rotor_count
        else:
            self._zero = self._idle = list(IDLE)
        self._handlers: dict[type[Any], Callable[[Any], CommandReply | Refusal | None]] = {
            Arm: self._arm,
            Disarm: self._disarm,
            Takeoff: self._takeoff,
            Land: lambda c: self._flying(self.modes.land),
            ReturnToLaunch: lambda c: self._flying(self.modes.rtl),
            Hold: lambda c: self._flying(self.modes.hold),
            Goto: self._goto,
            SetMode: self._set_mode,
            MissionUpload: lambda c: self._upload(list(c.items)),
            MissionStart: lambda c: self._flying(
                lambda est: self.modes.start_mission(est, c.start_index)
            ),
            MissionPause: self._pause,
            MissionClear: lambda c: self.modes.clear_mission(),
            MissionDownload: lambda c: self._reply(mission=self.mission_items()),
            Setpoint: lambda c: (
                self._plane_refuses("setpoints (offboard)") or self.modes.setpoint(c, self.now)
            ),
            GcsHeartbeat: self._heartbeat,
            SetParam: self._set_param,
            GetParams: lambda c: self._reply(params=self.params()),
            GeofenceUpload: lambda c: self.modes.upload_fence(self.est, list(c.zones)),
            RallyUpload: lambda c: self.modes.upload_rally([tuple(p) for p in c.points_enu_m]),
            Orbit: lambda c: (
                self._stall_check("orbit: speed_m_s", abs(c.speed_m_s))
                or self._flying(lambda est: self.modes.orbit(est, c))
            ),
        }

    def mission_items(self) -> list[MissionItem]:
        """The mission, including the scenario's before its upload at the first state.

        A ground station that connects before the lockstep runs downloads what the vehicle will
        fly, not an empty mission.
        """
        return list(self._scenario_mission or self.modes.mission.items)

    # ------------------------------------------------------------------ control tick
    def step(
        self,
        state: VehicleState,
        peers: Sequence[VehicleState] = (),
        readings: Sequence[ConcentrationReading] = (),
    ) -> list[float]:
        """Rotor commands (0..1) for this tick's state."""
        first = self.state is None
        self.state = state
        self.now = now = state.sim_time_s
        est = self.est = self.estimator.estimate(state)
        modes = self.modes
        if first and not state.on_ground and not state.crashed:
            # restarted mid-flight: take the vehicle back in hold where it is (never drop it)
            modes.resume_in_air(est, self._spawn)
            self.controller.reset()
            log.warning("%s: found in the air at start: armed, holding", self.vehicle_id)
        if not modes.armed:
            modes.home = est.position  # home follows the vehicle until it is armed
        if self._scenario_mission:
            refusal = self._upload(self._scenario_mission)
            if refusal is not None:
                log.error("%s: scenario mission refused: %s", self.vehicle_id, refusal.reason)
            self._scenario_mission = []
        self.monitor.check(est, state.crashed, now)
        if modes.mode == FlightMode.OFFBOARD and self.behavior is not None:
            self._run_behavior(state, peers, readings)
        target = modes.guidance(est, now)
        if self.pilot is not None:
            return self.pilot.update(est, target, now)
        assert self.mixer is not None
        if target is None:
            self.controller.reset()
            return self._idle if modes.mode == FlightMode.ARMED else self._zero
        thrust, tx, ty, tz = self.controller.update(est, target, integrate=not est.on_ground)
        return self.mixer.commands(thrust, tx, ty, tz)

    def _run_behavior(
        self,
        state: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> None:
        assert self.behavior is not None and self.est is not None
        try:
            setpoint = self.behavior.step(state, peers, readings)
        except Exception as exc:  # a plug-in must not take the vehicle down with it
            log.exception("%s: behaviour failed", self.vehicle_id)
            self.behavior_error = f"behaviour failed: {exc!r}"[:200]
            self.modes.failsafe_action(
                self.modes.failsafe.offboard_loss_action, self.est, self.behavior_error
            )
            return
        if setpoint is not None:
            refusal = self.modes.setpoint(setpoint, self.now)
            if refusal is not None:
                log.warning("%s: behaviour setpoint refused: %s", self.vehicle_id, refusal.reason)

    def state_lost(self, silent_s: float) -> None:
        """No tick, so no vehicle state, for ``silent_s`` seconds (realtime: wall seconds with
        the link to the physics down; lockstep and stepped: sim seconds the world stepped
        without this autopilot): land, as PX4 does when it loses its position estimate in the
        air. The mode stays after the ticks come back, until the pilot changes it."""
        if self.est is not None and self.modes.mode in AIRBORNE:
            reason = f"{STATE_LOST}: no tick for {silent_s:.1f} s"
            self.modes.failsafe_action("land", self.est, reason)

    # ------------------------------------------------------------------ commands
    def handle(self, command: Any) -> CommandReply:
        """Apply one decoded command; always returns a reply, never raises."""
        handler = self._handlers.get(type(command))
        if handler is None:
            return self._reply(RejectCode.UNSUPPORTED, f"unsupported command {type(command)}")
        try:
            result = handler(command)
        except Exception as exc:  # a bug here must not kill the process; say what happened
            log.exception("%s: command %s failed", self.vehicle_id, type(command).__name__)
            return self._reply(RejectCode.FAILED, f"internal error: {exc!r}"[:1000])
        if isinstance(result, CommandReply):
            return result
        if isinstance(result, Refusal):
            return self._reply(result.code, result.reason)
        return self._reply()

    def _reply(
        self,
        code: RejectCode = RejectCode.NONE,
        reason: str = "",
        **extra: Any,
    ) -> CommandReply:
        return CommandReply(
            vehicle_id=self.vehicle_id,
            accepted=code == RejectCode.NONE,
            code=code,
            reason=reason,
            **extra,
        )

    def _flying(self, action: Callable[[Estimate], Refusal | None]) -> Refusal | None:
        if self.est is None:
            return denied("no vehicle state yet (is the physics running?)")
        return action(self.est)

    def _arm(self, cmd: Arm) -> Refusal | None:
        if self.est is None:
            return denied("no vehicle state yet (is the physics running?)")
        if self.modes.failsafe.datalink_required and not self.monitor.gcs_link_ok(self.now):
            return denied("no ground-control link (failsafe.datalink_required)")
        refusal = self.modes.arm(self.est, crashed=self.monitor.crashed)
        if refusal is None:
            self.controller.reset()
        return refusal

    def _disarm(self, cmd: Disarm) -> Refusal | None:
        return self._flying(lambda est: self.modes.disarm(est, force=cmd.force))

    def _takeoff(self, cmd: Takeoff) -> Refusal | None:
        return self._flying(lambda est: self.modes.takeoff(est, cmd.altitude_m))

    @property
    def kind(self) -> str:
        """The vehicle kind (``multirotor``, ``fixed_wing``): what a MAVLink heartbeat's
        vehicle type and custom modes follow."""
        return self.vehicle_type.kind

    def _plane_refuses(self, what: str) -> Refusal | None:
        if self.vehicle_type.fixed_wing is None:
            return None
        return Refusal(
            RejectCode.UNSUPPORTED,
            f"{what}: not flown by the fixed-wing controller (it flies takeoff, hold, goto, "
            "mission, orbit, land and rtl)",
        )

    def _stall_check(self, what: str, speed_m_s: float) -> Refusal | None:
        """A fixed wing refuses an airspeed below FW_AIRSPD_MIN (stall) or above
        FW_AIRSPD_MAX; 0 means FW_AIRSPD_TRIM."""
        if self.pilot is None or speed_m_s == 0.0:
            return None
        p = self.pilot.p
        if speed_m_s < p.fw_airspd_min:
            return invalid(
                f"{what} {speed_m_s:g} m/s is below FW_AIRSPD_MIN {p.fw_airspd_min:g} m/s "
                f"(stall); valid: 0 (FW_AIRSPD_TRIM {p.fw_airspd_trim:g}) or "
                f"{p.fw_airspd_min:g}..{p.fw_airspd_max:g}"
            )
        if speed_m_s > p.fw_airspd_max:
            return invalid(
                f"{what} {speed_m_s:g} m/s is above FW_AIRSPD_MAX {p.fw_airspd_max:g} m/s; "
                f"valid: 0 or {p.fw_airspd_min:g}..{p.fw_airspd_max:g}"
            )
        return None

    def _upload(self, items: list[MissionItem]) -> Refusal | None:
        for i, item in enumerate(items):
            refusal = self._stall_check(f"item {i}: speed_m_s", item.speed_m_s)
            if refusal is not None:
                return refusal
        return self.modes.upload_mission(items)

    def _goto(self, cmd: Goto) -> Refusal | None:
        refusal = self._stall_check("goto: speed_m_s", cmd.speed_m_s)
        if refusal is not None:
            return refusal
        yaw = math.radians(cmd.yaw_deg) if cmd.yaw_deg is not None else None
        return self._flying(
            lambda est: self.modes.goto(est, cmd.position_enu_m, yaw, cmd.speed_m_s)
        )

    def _pause(self, cmd: MissionPause) -> Refusal | None:
        if self.modes.mode != FlightMode.MISSION:
            return denied(f"no mission flying (mode {self.modes.mode})")
        return self._flying(self.modes.hold)

    def _set_mode(self, cmd: SetMode) -> Refusal | None:
        m = self.modes
        actions: dict[FlightMode, Callable[[Estimate], Refusal | None]] = {
            FlightMode.DISARMED: lambda est: m.disarm(est),
            FlightMode.ARMED: lambda est: self._arm(Arm()),
            FlightMode.TAKEOFF: lambda est: m.takeoff(est, m.failsafe.takeoff_altitude_m),
            FlightMode.HOLD: m.hold,
            FlightMode.MISSION: lambda est: m.start_mission(est, None),
            FlightMode.LAND: m.land,
            FlightMode.RTL: m.rtl,
            FlightMode.OFFBOARD: lambda est: m.offboard(est, self.now),
            FlightMode.ORBIT: lambda est: denied("orbit needs a centre: send an Orbit command"),
            FlightMode.POSITION: lambda est: m.position_mode(est, self.now),
            FlightMode.FOLLOW: m.follow,
        }
        if cmd.mode == m.mode:
            return None
        if cmd.mode in (FlightMode.OFFBOARD, FlightMode.POSITION, FlightMode.FOLLOW):
            refusal = self._plane_refuses(f"mode {cmd.mode}")
            if refusal is not None:
                return refusal
        return self._flying(actions[cmd.mode])

    def _heartbeat(self, cmd: GcsHeartbeat) -> None:
        self.monitor.heartbeat(self.now)

    def params(self) -> dict[str, float]:
        fs = self.modes.failsafe
        out: dict[str, float] = {}
        for name, field in _PARAMS.items():
            value = getattr(fs, field)
            if isinstance(value, str):
                out[name] = float(ACTION_CODES_OF_PARAM[name][value])
            else:
                out[name] = float(value)
        if self.pilot is not None:  # a fixed wing: its PX4 parameters, by their PX4 names
            out.update(msgspec.to_builtins(self.pilot.p))
        return out

    def _set_fixed_wing_param(self, cmd: SetParam) -> CommandReply | Refusal:
        """A PX4 fixed-wing parameter: valid by the type's bounds, FW_AIRSPD_MIN not below
        the stall speed and MIN <= TRIM <= MAX; in effect from the next control tick."""
        assert self.pilot is not None
        wanted = {**msgspec.to_builtins(self.pilot.p), cmd.name: cmd.value}
        try:
            p = msgspec.convert(wanted, FixedWingParams)
        except msgspec.ValidationError as exc:
            return invalid(f"{cmd.name}: {exc}")
        stall = self.vehicle_type.stall_speed_m_s
        if p.fw_airspd_min < stall:
            return invalid(
                f"FW_AIRSPD_MIN {p.fw_airspd_min:g} m/s is below the stall speed "
                f"{stall:.1f} m/s of {self.vehicle_type.name}; valid: {stall:.1f}.."
                f"FW_AIRSPD_TRIM {p.fw_airspd_trim:g}"
            )
        if not p.fw_airspd_min <= p.fw_airspd_trim <= p.fw_airspd_max:
            return invalid(
                f"{cmd.name}: {cmd.value:g} breaks FW_AIRSPD_MIN <= FW_AIRSPD_TRIM <= "
                f"FW_AIRSPD_MAX ({p.fw_airspd_min:g}, {p.fw_airspd_trim:g}, {p.fw_airspd_max:g})"
            )
        self.pilot.set_params(p)
        return self._reply(params=self.params())

    def _set_param(self, cmd: SetParam) -> CommandReply | Refusal:
        field = _PARAMS.get(cmd.name)
        if field is None and self.pilot is not None and cmd.name in _FIXED_WING_PARAMS:
            return self._set_fixed_wing_param(cmd)
        if field is None:
            return Refusal(RejectCode.UNSUPPORTED, f"unknown parameter {cmd.name!r}")
        fs = self.modes.failsafe
        value: Any = cmd.value
        if isinstance(getattr(fs, field), str):
            codes = ACTION_CODES_OF_PARAM[cmd.name]
            value = {float(v): k for k, v in codes.items()}.get(float(cmd.value))
            if value is None:
                known = ", ".join(f"{v} {k}" for k, v in codes.items())
                return invalid(f"{cmd.name}: {cmd.value:g} is not an action code ({known})")
        try:
            self.modes.failsafe = msgspec.convert(
                {**msgspec.structs.asdict(fs), field: value}, type(fs)
            )
        except msgspec.ValidationError as exc:
            return invalid(f"{cmd.name}: {exc}")
        return self._reply(params=self.params())

    # ------------------------------------------------------------------ status
    def status(self) -> VehicleStatus:
        m = self.modes
        mission = m.mission
        state = self.state
        health = self.behavior_error or self.sensor_health or "ok"
        return VehicleStatus(
            vehicle_id=self.vehicle_id,
            sim_time_s=self.now,
            mode=m.mode,
            armed=m.armed,
            landed=state.on_ground if state is not None else True,
            crashed=self.monitor.crashed,
            mission_index=mission.index,
            mission_count=mission.count or len(self._scenario_mission),  # see mission_items
            mission_items_reached=mission.items_reached,
            mission_finished=mission.finished,
            home_enu_m=m.home,
            failsafe=m.failsafe_reason,
            health=health,
        )
