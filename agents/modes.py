"""Flight modes: an explicit state machine over a transition table (:mod:`agents.mode_table`),
and per-mode guidance. Guards that depend on more than the
mode (arming in the air, an empty mission, no setpoint stream, the geofence, …) are checked in
the action methods. Guidance (``FlightModes.guidance``) turns the mode into a controller
:class:`~agents.control.Target` every tick and makes the automatic transitions (take-off done →
hold, touchdown → disarmed, offboard stream lost → the configured action, …).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Concatenate, ParamSpec

from agents.control import Estimate, Target, yaw_of
from agents.geofence import zone_error, zones_violation
from agents.mission import Mission, MissionError, ResolvedItem
from agents.mode_table import (
    AIRBORNE,
    REFUSALS,
    TRANSITIONS,
    Action,
    M,
    Refusal,
    RtlPhase,
    denied,
    invalid,
)
from swarmbus.messages import (
    FenceZone,
    FlightMode,
    MissionCommand,
    MissionItem,
    Orbit,
    OrbitYaw,
    Setpoint,
)
from swarmbus.scenario import Failsafe, Origin

TAKEOFF_DONE_M = 0.3  # altitude error at which take-off hands over to hold
TOUCHDOWN_SPEED_M_S = 0.5
TOUCHDOWN_TIME_S = 0.5
LAND_SLOW_BELOW_M = 4.0  # height above home under which the descent slows down
LAND_SLOW_SPEED_M_S = 0.6
RTL_HOME_RADIUS_M = 1.0


P = ParamSpec("P")


def _guarded(
    action: Action,
) -> Callable[
    [Callable[Concatenate[FlightModes, FlightMode, P], Refusal | None]],
    Callable[Concatenate[FlightModes, P], Refusal | None],
]:
    """An action the mode table guards: refused with the table's reason (:data:`REFUSALS`)
    unless :data:`TRANSITIONS` allow ``action`` in the current mode; otherwise the method runs,
    given the mode the action leads to (it checks the rest and changes the mode)."""

    def wrap(
        body: Callable[Concatenate[FlightModes, FlightMode, P], Refusal | None],
    ) -> Callable[Concatenate[FlightModes, P], Refusal | None]:
        def act(modes: FlightModes, /, *args: P.args, **kwargs: P.kwargs) -> Refusal | None:
            to = modes._allowed(action)
            if isinstance(to, Refusal):
                return to
            return body(modes, to, *args, **kwargs)

        functools.update_wrapper(act, body)
        return act

    return wrap


class FlightModes:
    """Mode, home, targets and mission of one vehicle; no I/O, no wall clock."""

    def __init__(self, failsafe: Failsafe, origin: Origin) -> None:
        self.failsafe = failsafe
        self.origin = origin
        self.mode = M.DISARMED
        self.mission = Mission()
        self.home: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.fence_zones: list[FenceZone] = []  # uploaded polygons and circles
        self.rally_points: list[tuple[float, float, float]] = []
        self._rtl_dest: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self.failsafe_reason = ""  # why the last automatic (failsafe) transition happened
        self.has_behavior = False
        self._target: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._yaw = 0.0
        self._speed = 0.0
        self._touchdown_since: float | None = None
        self._rtl_phase = RtlPhase.CLIMB
        self._rtl_alt = 0.0
        self._setpoint: Setpoint | None = None
        self._setpoint_time_s = -math.inf
        self._offboard_tick_s = -math.inf
        self._item_seen = -1
        self._land_descending = False
        self._climb_altitude_m: float | None = None  # a mission started on the ground climbs first
        self._guidance: dict[FlightMode, Callable[[Estimate, float], Target | None]] = {
            M.DISARMED: lambda est, now: None,
            M.ARMED: lambda est, now: None,
            M.TAKEOFF: self._guide_takeoff,
            M.HOLD: self._guide_hold,
            M.MISSION: self._guide_mission,
            M.LAND: self._guide_land,
            M.RTL: self._guide_rtl,
            M.OFFBOARD: self._guide_offboard,
            M.ORBIT: self._guide_orbit,
            M.POSITION: self._guide_position,
            M.FOLLOW: self._guide_follow,
        }
        self._orbit: Orbit | None = None
        # A fixed wing's pilot decides when a mission waypoint is reached (it cannot stop on
        # it: a horizontal radius, a loiter circle); None: the 3-D acceptance radius.
        self.waypoint_reached: Callable[[ResolvedItem, Estimate], bool] | None = None

    @property
    def orbit_command(self) -> Orbit | None:
        """The orbit being flown (mode ORBIT)."""
        return self._orbit

    @property
    def rtl_target(self) -> tuple[tuple[float, float, float], float]:
        """Where RTL returns to and the altitude it flies at."""
        return self._rtl_dest, self._rtl_alt

    def landed(self, est: Estimate, now: float) -> None:
        """A fixed wing stopped on the ground after its landing: the land item is reached,
        the vehicle disarms (a multirotor's touchdown is detected in guidance)."""
        item = self.mission.current
        if self.mode == M.MISSION and item is not None and item.command == MissionCommand.LAND:
            self.mission.reached(now)
        if self.mode in (M.MISSION, M.LAND, M.RTL):
            self._set_mode(M.DISARMED, est)

    # ------------------------------------------------------------------ table
    @property
    def armed(self) -> bool:
        return self.mode != M.DISARMED

    def _allowed(self, action: Action) -> FlightMode | Refusal:
        to = TRANSITIONS[action].get(self.mode)
        if to is None:
            return denied(REFUSALS[action].get(self.mode, f"not allowed in mode {self.mode}"))
        return to

    def _set_mode(self, mode: FlightMode, est: Estimate) -> None:
        self.mode = mode
        self._touchdown_since = None
        if mode != M.MISSION:
            self._climb_altitude_m = None
        if mode in (M.HOLD, M.TAKEOFF, M.OFFBOARD):
            self._yaw = yaw_of(est.attitude_xyzw)

    def _hold_here(self, est: Estimate) -> None:
        self._target = est.position
        self._speed = 0.0
        self._yaw = yaw_of(est.attitude_xyzw)

    def fence_violation(self, x: float, y: float, z: float) -> str | None:
        """Which geofence limit a point breaks, named by its PX4 parameter (0 = off, as PX4)."""
        fs = self.failsafe
        hx, hy, hz = self.home
        if fs.geofence_max_altitude_m > 0.0 and z - hz > fs.geofence_max_altitude_m:
            return f"GF_MAX_VER_DIST {fs.geofence_max_altitude_m:g} m: {z - hz:.1f} m above home"
        dist = math.hypot(x - hx, y - hy)
        if fs.geofence_max_distance_m > 0.0 and dist > fs.geofence_max_distance_m:
            return f"GF_MAX_HOR_DIST {fs.geofence_max_distance_m:g} m: {dist:.1f} m from home"
        return zones_violation(self.fence_zones, x, y) if self.fence_zones else None

    def upload_fence(self, est: Estimate | None, zones: list[FenceZone]) -> Refusal | None:
        """Replace the uploaded zones. As PX4 does, a fence that leaves out home (or, before
        arming, where the vehicle stands) is refused."""
        for i, zone in enumerate(zones):
            why = zone_error(zone)
            if why is not None:
                return invalid(f"zone {i}: {why}")
        here = self.home if self.armed or est is None else est.position
        if est is not None or self.armed:
            outside = zones_violation(zones, here[0], here[1])
            if outside is not None:
                return invalid(f"home is not allowed by the fence ({outside})")
        self.fence_zones = list(zones)
        return None

    def upload_rally(self, points: list[tuple[float, float, float]]) -> Refusal | None:
        self.rally_points = list(points)
        return None

    # ------------------------------------------------------------------ actions
    @_guarded(Action.ARM)
    def arm(self, to: FlightMode, est: Estimate, crashed: bool = False) -> Refusal | None:
        if crashed:
            return denied("crashed: the vehicle cannot be armed again")
        if not est.on_ground:
            return denied("in the air: arming in the air is refused")
        self.home = est.position
        self._hold_here(est)
        self._set_mode(to, est)
        self.failsafe_reason = ""
        return None

    def resume_in_air(self, est: Estimate, home: tuple[float, float, float]) -> None:
        """Take back a vehicle found flying (a restarted autopilot): armed, holding here."""
        self.home = home
        self._hold_here(est)
        self._set_mode(M.HOLD, est)
        self.failsafe_reason = "autopilot restarted in the air: holding"

    @_guarded(Action.DISARM)
    def disarm(self, to: FlightMode, est: Estimate, force: bool = False) -> Refusal | None:
        if self.mode in AIRBORNE and not est.on_ground and not force:
            return denied("in the air: disarming would drop the vehicle (use force)")
        self._set_mode(to, est)
        return None

    @_guarded(Action.TAKEOFF)
    def takeoff(self, to: FlightMode, est: Estimate, altitude_m: float) -> Refusal | None:
        x, y, _ = est.position
        z = self.home[2] + altitude_m
        fence = self.fence_violation(x, y, z)
        if fence is not None:
            return invalid(f"takeoff: {fence}")
        self._target = (x, y, z)
        self._speed = 0.0
        self._set_mode(to, est)
        return None

    @_guarded(Action.LAND)
    def land(self, to: FlightMode, est: Estimate) -> Refusal | None:
        self._target = est.position
        self._set_mode(to, est)
        return None

    @_guarded(Action.RTL)
    def rtl(self, to: FlightMode, est: Estimate) -> Refusal | None:
        self._rtl_phase = RtlPhase.CLIMB
        self._rtl_alt = max(est.position[2], self.home[2] + self.failsafe.rtl_altitude_m)
        # PX4's default RTL_TYPE 0: the closest safe point, home or a rally point
        x, y, _ = est.position
        self._rtl_dest = min(
            [self.home, *self.rally_points], key=lambda p: math.hypot(p[0] - x, p[1] - y)
        )
        self._target = est.position
        self._set_mode(to, est)
        return None

    @_guarded(Action.HOLD)
    def hold(self, to: FlightMode, est: Estimate) -> Refusal | None:
        self._hold_here(est)
        self._set_mode(to, est)
        return None

    @_guarded(Action.GOTO)
    def goto(
        self,
        to: FlightMode,
        est: Estimate,
        position: tuple[float, float, float],
        yaw_rad: float | None,
        speed_m_s: float,
    ) -> Refusal | None:
        fence = self.fence_violation(*position)
        if fence is not None:
            return invalid(f"goto: {fence}")
        self._set_mode(to, est)
        self._target = position
        self._speed = speed_m_s
        if yaw_rad is not None:
            self._yaw = yaw_rad
        return None

    @_guarded(Action.ORBIT)
    def orbit(self, to: FlightMode, est: Estimate, orbit: Orbit) -> Refusal | None:
        cx, cy, cz = orbit.center_enu_m
        for k in range(8):  # the circle, sampled, must lie inside the fence
            a = k * math.pi / 4.0
            r = orbit.radius_m
            fence = self.fence_violation(cx + r * math.cos(a), cy + r * math.sin(a), cz)
            if fence is not None:
                return invalid(f"orbit: {fence}")
        self._set_mode(to, est)
        self._orbit = orbit
        return None

    def upload_mission(self, items: list[MissionItem]) -> Refusal | None:
        if self.mode == M.MISSION:
            return denied("a mission is flying: pause it (hold) before replacing it")
        try:
            self.mission.upload(items, self.origin)
        except MissionError as exc:
            return invalid(str(exc))
        for i, item in enumerate(self.mission.resolved):
            fence = self.fence_violation(item.x, item.y, item.z)
            if fence is not None and item.command != MissionCommand.RTL:
                self.mission.clear()
                return invalid(f"item {i}: {fence}")
        self._item_seen = -1
        return None

    def clear_mission(self) -> Refusal | None:
        if self.mode == M.MISSION:
            return denied("a mission is flying: pause it (hold) before clearing it")
        self.mission.clear()
        return None

    @_guarded(Action.MISSION)
    def start_mission(
        self, to: FlightMode, est: Estimate, start_index: int | None
    ) -> Refusal | None:
        """``start_index`` None resumes at the current item (set mode mission)."""
        mission = self.mission
        if mission.count == 0:
            return denied("no mission uploaded")
        if start_index is not None and start_index >= mission.count:
            return invalid(f"start_index {start_index}: mission has {mission.count} item(s)")
        index = start_index if start_index is not None else max(mission.index, 0)
        if start_index is None and mission.finished:
            return denied("mission finished: start it again with a start index")
        climb_altitude_m = None
        first = mission.resolved[index]
        if self.mode == M.ARMED and first.command != MissionCommand.TAKEOFF:
            # PX4: a mission started on the ground without a takeoff item climbs vertically to
            # the first item's altitude, at least MIS_TAKEOFF_ALT above home, then flies it.
            climb_altitude_m = max(first.z, self.home[2] + self.failsafe.takeoff_altitude_m)
            x, y, _ = est.position
            fence = self.fence_violation(x, y, climb_altitude_m)
            if fence is not None:
                return invalid(f"mission takeoff: {fence}")
        if start_index is not None:
            mission.start(start_index)
        self._item_seen = -1
        self._set_mode(to, est)
        if climb_altitude_m is not None:
            self._climb_altitude_m = climb_altitude_m
            self._target = est.position
        return None

    def setpoint(self, setpoint: Setpoint, now: float) -> Refusal | None:
        sp = setpoint
        direct = sp.attitude_xyzw is not None or sp.body_rates_rad_s is not None
        if direct and sp.thrust is None:
            return invalid("an attitude or body-rate setpoint needs a thrust")
        if not direct and (
            sp.position_enu_m is None
            and sp.velocity_enu_m_s is None
            and sp.acceleration_enu_m_s2 is None
        ):
            return invalid(
                "setpoint needs a position, velocity, acceleration, attitude or body rates"
            )
        if setpoint.position_enu_m is not None:
            fence = self.fence_violation(*setpoint.position_enu_m)
            if fence is not None and self.armed:
                return invalid(f"setpoint: {fence}")
        self._setpoint = setpoint
        self._setpoint_time_s = now
        return None

    @_guarded(Action.OFFBOARD)
    def offboard(self, to: FlightMode, est: Estimate, now: float) -> Refusal | None:
        if not self.has_behavior and not self._stream_alive(now):
            return denied("no offboard setpoint stream: send setpoints first")
        self._hold_here(est)
        self._set_mode(to, est)
        self._offboard_tick_s = -math.inf
        if self.has_behavior:  # the behaviour is the stream; it starts now
            self._setpoint_time_s = now
        return None

    @_guarded(Action.POSITION)
    def position_mode(self, to: FlightMode, est: Estimate, now: float) -> Refusal | None:
        """PX4's position mode: the ground station's sticks arrive as setpoints (velocity,
        yaw rate); centred sticks hold. Needs the stick stream, as offboard needs its own."""
        if not self._stream_alive(now):
            return denied("no manual control input: send MANUAL_CONTROL first")
        self._hold_here(est)
        self._set_mode(to, est)
        self._offboard_tick_s = -math.inf
        return None

    @_guarded(Action.FOLLOW)
    def follow(self, to: FlightMode, est: Estimate) -> Refusal | None:
        """PX4's follow-me: hold here until target setpoints arrive, fly them while they do,
        hold where they stopped when they stop (the target is lost)."""
        self._hold_here(est)
        self._set_mode(to, est)
        self._setpoint = None
        self._offboard_tick_s = -math.inf
        return None

    def _guide_follow(self, est: Estimate, now: float) -> Target | None:
        if self._setpoint is None or not self._stream_alive(now):
            if self._setpoint is not None:
                self._hold_here(est)
                self._setpoint = None
            return self._position_target()
        return self._guide_offboard(est, now)

    def _guide_position(self, est: Estimate, now: float) -> Target | None:
        if not self._stream_alive(now):
            self.failsafe_action("hold", est, "manual control input lost")
            return self.guidance(est, now)
        return self._guide_offboard(est, now)

    def _stream_alive(self, now: float) -> bool:
        return now - self._setpoint_time_s <= self.failsafe.offboard_timeout_s

    # ------------------------------------------------------------------ failsafe entry
    def failsafe_action(self, action: str, est: Estimate, reason: str) -> None:
        """Apply a configured failsafe action ("none", "hold", "land", "rtl") when airborne."""
        self.failsafe_reason = reason
        if self.mode not in AIRBORNE or action == "none":
            return
        if action == "hold":
            self.hold(est)
        elif action == "land" and self.mode != M.LAND:
            self.land(est)
        elif action == "rtl" and self.mode not in (M.RTL, M.LAND):
            self.rtl(est)

    def crashed(self, est: Estimate) -> None:
        self.failsafe_reason = "crash"
        self._set_mode(M.DISARMED, est)

    # ------------------------------------------------------------------ guidance
    def guidance(self, est: Estimate, now: float) -> Target | None:
        """The controller target for this tick (``None``: motors off or idle)."""
        return self._guidance[self.mode](est, now)

    def _position_target(self, speed: float = 0.0) -> Target:
        x, y, z = self._target
        return Target((x, y), z, self._yaw, max_speed_xy_m_s=speed)

    def _guide_takeoff(self, est: Estimate, now: float) -> Target | None:
        if abs(est.position[2] - self._target[2]) < TAKEOFF_DONE_M:
            self._set_mode(M.HOLD, est)
        return self._position_target()

    def _guide_hold(self, est: Estimate, now: float) -> Target | None:
        return self._position_target(self._speed)

    def _descend(self, est: Estimate, now: float, xy: tuple[float, float]) -> Target | None:
        """Descend over ``xy``; on touchdown disarm and return ``None``."""
        speed = math.sqrt(est.velocity[0] ** 2 + est.velocity[1] ** 2 + est.velocity[2] ** 2)
        if est.on_ground and speed < TOUCHDOWN_SPEED_M_S:
            if self._touchdown_since is None:
                self._touchdown_since = now
            if now - self._touchdown_since >= TOUCHDOWN_TIME_S:
                self._set_mode(M.DISARMED, est)
                return None
        else:
            self._touchdown_since = None
        height = est.position[2] - self.home[2]
        # far above ground: as fast as allowed (the controller clips to its max descent speed)
        vz = -LAND_SLOW_SPEED_M_S if height < LAND_SLOW_BELOW_M else -100.0
        return Target(xy, None, self._yaw, velocity=(0.0, 0.0, vz))

    def _guide_land(self, est: Estimate, now: float) -> Target | None:
        return self._descend(est, now, (self._target[0], self._target[1]))

    def _guide_rtl(self, est: Estimate, now: float) -> Target | None:
        hx, hy, _ = self._rtl_dest
        x, y, z = est.position
        if self._rtl_phase == RtlPhase.CLIMB:
            if z >= self._rtl_alt - TAKEOFF_DONE_M:
                self._rtl_phase = RtlPhase.RETURN
            return Target((self._target[0], self._target[1]), self._rtl_alt, self._yaw)
        if self._rtl_phase == RtlPhase.RETURN:
            if math.hypot(x - hx, y - hy) < RTL_HOME_RADIUS_M:
                self._rtl_phase = RtlPhase.DESCEND
            return Target((hx, hy), self._rtl_alt, self._yaw)
        return self._descend(est, now, (hx, hy))

    def _guide_mission(self, est: Estimate, now: float) -> Target | None:
        mission = self.mission
        item = mission.current
        if item is None:  # finished: hold where the last item left us
            self._hold_here(est)
            self._set_mode(M.HOLD, est)
            return self._position_target()
        if self._climb_altitude_m is not None:
            if est.position[2] < self._climb_altitude_m - TAKEOFF_DONE_M:
                tx, ty, _ = self._target
                return Target((tx, ty), self._climb_altitude_m, self._yaw)
            self._climb_altitude_m = None
        if mission.index != self._item_seen:
            self._start_item(item, est)
        if item.command == MissionCommand.RTL:
            mission.reached(now)
            self.rtl(est)
            return self._guide_rtl(est, now)
        if item.command == MissionCommand.TAKEOFF:
            return self._mission_takeoff(item, est, now)
        if item.command == MissionCommand.LAND:
            return self._mission_land(item, est, now)
        x, y, z = est.position
        if self.waypoint_reached is not None:
            inside = self.waypoint_reached(item, est)
        else:
            dist = math.sqrt((x - item.x) ** 2 + (y - item.y) ** 2 + (z - item.z) ** 2)
            inside = dist < item.acceptance_radius_m
        if inside and mission.arrived(now):
            return self._guide_mission(est, now)
        return Target((item.x, item.y), item.z, self._yaw, max_speed_xy_m_s=item.speed_m_s)

    def _start_item(self, item: ResolvedItem, est: Estimate) -> None:
        """A mission item seen for the first time: it starts from where the vehicle is."""
        self._item_seen = self.mission.index
        self._target = est.position
        self._land_descending = False
        if item.yaw_rad is not None:
            self._yaw = item.yaw_rad

    def _mission_takeoff(self, item: ResolvedItem, est: Estimate, now: float) -> Target | None:
        tx, ty, _ = self._target
        if abs(est.position[2] - item.z) < item.acceptance_radius_m and self.mission.arrived(now):
            return self._guide_mission(est, now)
        return Target((tx, ty), item.z, self._yaw, max_speed_xy_m_s=item.speed_m_s)

    def _mission_land(self, item: ResolvedItem, est: Estimate, now: float) -> Target | None:
        """Fly to the item's point at the item's height, then descend there and land."""
        if not self._land_descending:
            x, y, _ = est.position
            if math.hypot(x - item.x, y - item.y) < item.acceptance_radius_m:
                self._land_descending = True
            else:
                return Target(
                    (item.x, item.y), self._target[2], self._yaw, max_speed_xy_m_s=item.speed_m_s
                )
        target = self._descend(est, now, (item.x, item.y))
        if target is None:
            self.mission.reached(now)
        return target

    def _guide_orbit(self, est: Estimate, now: float) -> Target | None:
        """On the circle at the vehicle's bearing from the centre, the tangential speed as
        feed-forward (the position loop pulls in the radial error)."""
        o = self._orbit
        if o is None:
            return self._position_target()
        cx, cy, cz = o.center_enu_m
        theta = math.atan2(est.position[1] - cy, est.position[0] - cx)
        omega = -o.speed_m_s / o.radius_m  # clockwise (positive speed) is negative in ENU
        tangent = (-math.sin(theta) * omega * o.radius_m, math.cos(theta) * omega * o.radius_m)
        if o.yaw == OrbitYaw.CENTRE:
            self._yaw = theta + math.pi
        elif o.yaw == OrbitYaw.TANGENT:
            self._yaw = theta + math.copysign(math.pi / 2.0, omega)
        on_circle = (cx + o.radius_m * math.cos(theta), cy + o.radius_m * math.sin(theta))
        return Target(on_circle, cz, self._yaw, velocity=(*tangent, 0.0))

    def _guide_offboard(self, est: Estimate, now: float) -> Target | None:
        if not self._stream_alive(now):
            self.failsafe_action(
                self.failsafe.offboard_loss_action, est, "offboard setpoint stream lost"
            )
            return self.guidance(est, now)
        sp = self._setpoint
        dt = now - self._offboard_tick_s if math.isfinite(self._offboard_tick_s) else 0.0
        self._offboard_tick_s = now
        if sp is None:
            return self._position_target()
        if sp.yaw_deg is not None:
            self._yaw = math.radians(sp.yaw_deg)
        elif sp.yaw_rate_deg_s is not None:
            self._yaw = (self._yaw + math.radians(sp.yaw_rate_deg_s) * dt + math.pi) % (
                2.0 * math.pi
            ) - math.pi
        thrust = sp.thrust or 0.0
        if sp.body_rates_rad_s is not None:
            return Target(
                None, None, self._yaw, body_rates=sp.body_rates_rad_s, thrust_fraction=thrust
            )
        if sp.attitude_xyzw is not None:
            return Target(None, None, self._yaw, attitude=sp.attitude_xyzw, thrust_fraction=thrust)
        velocity = sp.velocity_enu_m_s or (0.0, 0.0, 0.0)
        accel = sp.acceleration_enu_m_s2 or (0.0, 0.0, 0.0)
        if sp.position_enu_m is None:
            loop = sp.velocity_enu_m_s is not None
            return Target(None, None, self._yaw, velocity, acceleration=accel, velocity_loop=loop)
        px, py, pz = sp.position_enu_m
        return Target((px, py), pz, self._yaw, velocity=velocity, acceleration=accel)
