"""A scripted stand-in for physics + autopilots, speaking only the bus contract.

``python -m tests.support.fake_autopilot --connect EP --scenario F [--speed X] [--skip ID]``
serves every vehicle of the scenario but the skipped ones: a liveliness token
``autopilot-<id>``, the ``vehicle/<id>/cmd`` queryable with the contract's replies (the same
mode rules as the autopilot: arm on the ground, take off only when armed, missions need an
upload, …), and tick (``sim/tick``, as the physics) / state / status / concentration
publications with kinematic motion at 120 Hz of sim time, paced at ``--speed`` × real time.
The gateway's tests fly many vehicles against it without the cost of pybullet and one
autopilot per vehicle; it flies nothing for real.

:class:`FakeAutopilot` is one vehicle's autopilot as the bus sees it (the token, the command
queryable served through ``swarmbus.reqrep``, the status publisher) with the answers left to
its owner: this process answers with the mode rules of :class:`World`, a test that plays a
vehicle itself (tests/gcs_bridge/test_gateway_flows.py) with a script of its own.
"""

from __future__ import annotations

import argparse
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import pymap3d
import zenoh

from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    Command,
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
    MissionCommand,
    MissionDownload,
    MissionFrame,
    MissionItem,
    MissionPause,
    MissionStart,
    MissionUpload,
    RallyUpload,
    RejectCode,
    ReturnToLaunch,
    SetMode,
    SetParam,
    Setpoint,
    SimTick,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.reqrep import Incoming, serve_later
from swarmbus.scenario import Scenario, load_scenario
from swarmbus.session import NetworkConfig, open_session

M = FlightMode
AIRBORNE = {M.TAKEOFF, M.HOLD, M.MISSION, M.LAND, M.RTL, M.OFFBOARD}
DT = 1.0 / 120.0
XY_SPEED = 8.0
Z_SPEED = 3.0
PARAMS = {
    "NAV_DLL_ACT": 2.0,
    "COM_DL_LOSS_T": 10.0,
    "RTL_RETURN_ALT": 15.0,
    "GF_MAX_VER_DIST": 120.0,
    "GF_MAX_HOR_DIST": 500.0,
    "MIS_TAKEOFF_ALT": 10.0,
}


@dataclass
class Fake:
    vid: str
    pos: list[float]
    mode: FlightMode = M.DISARMED
    home: tuple[float, float, float] = (0.0, 0.0, 0.0)
    target: tuple[float, float, float] = (0.0, 0.0, 0.0)
    items: list[MissionItem] = field(default_factory=list)
    index: int = -1
    reached: int = 0
    finished: bool = False
    params: dict[str, float] = field(default_factory=lambda: dict(PARAMS))
    gcs_heartbeats: int = 0
    vel: tuple[float, float, float] = (0.0, 0.0, 0.0)
    descending: bool = False
    climb_to: float | None = None  # a mission started on the ground climbs first (PX4)

    @property
    def on_ground(self) -> bool:
        return self.pos[2] <= self.home[2] + 0.05 and self.mode not in (M.TAKEOFF,)


def refuse(vid: str, code: RejectCode, reason: str) -> CommandReply:
    return CommandReply(vehicle_id=vid, accepted=False, code=code, reason=reason)


class World:
    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self.origin = scenario.world.origin
        self.lock = threading.Lock()
        self.t = 0.0
        self.vehicles = {
            v.id: Fake(v.id, list(v.spawn_enu_m), home=v.spawn_enu_m) for v in scenario.vehicles
        }
        o = self.origin
        lat1, lon1, _ = pymap3d.enu2geodetic(1.0, 1.0, 0.0, o.lat_deg, o.lon_deg, o.alt_m)
        self.deg_per_m = (float(lon1) - o.lon_deg, float(lat1) - o.lat_deg)
        for v in scenario.vehicles:  # the scenario's mission is loaded, as the autopilot does
            f = self.vehicles[v.id]
            f.items, f.index = list(v.mission), (0 if v.mission else -1)

    # ------------------------------------------------------------------ commands
    def handle(self, f: Fake, cmd: Command) -> CommandReply:
        for part in (self._admin, self._arming, self._mission, self._flight):
            reply = part(f, cmd)
            if reply is not None:
                return reply
        return refuse(f.vid, RejectCode.UNSUPPORTED, f"{type(cmd).__name__} not faked")

    def _admin(self, f: Fake, cmd: Command) -> CommandReply | None:
        """Heartbeats, parameters, and what the fake accepts and ignores."""
        if isinstance(cmd, GcsHeartbeat):
            f.gcs_heartbeats += 1
            return CommandReply(vehicle_id=f.vid, accepted=True)
        if isinstance(cmd, GetParams):
            return CommandReply(vehicle_id=f.vid, accepted=True, params=dict(f.params))
        if isinstance(cmd, SetParam):
            if cmd.name not in f.params:
                return refuse(f.vid, RejectCode.UNSUPPORTED, f"unknown parameter {cmd.name}")
            f.params[cmd.name] = cmd.value
            return CommandReply(vehicle_id=f.vid, accepted=True, params=dict(f.params))
        if isinstance(cmd, Setpoint | GeofenceUpload | RallyUpload):
            return CommandReply(vehicle_id=f.vid, accepted=True)
        return None

    def _arming(self, f: Fake, cmd: Command) -> CommandReply | None:
        denied = RejectCode.DENIED
        here = (f.pos[0], f.pos[1], f.pos[2])
        if isinstance(cmd, Arm):
            if f.mode != M.DISARMED:
                return refuse(f.vid, denied, "already armed")
            f.mode, f.home, f.target = M.ARMED, here, here
        elif isinstance(cmd, Disarm):
            if f.mode == M.DISARMED:
                return refuse(f.vid, denied, "already disarmed")
            if f.mode in AIRBORNE and not f.on_ground and not cmd.force:
                return refuse(f.vid, denied, "in the air")
            f.mode = M.DISARMED
        elif isinstance(cmd, Takeoff):
            if f.mode != M.ARMED:
                return refuse(f.vid, denied, "arm before taking off")
            f.mode, f.target = M.TAKEOFF, (here[0], here[1], f.home[2] + cmd.altitude_m)
        else:
            return None
        return CommandReply(vehicle_id=f.vid, accepted=True)

    def _mission(self, f: Fake, cmd: Command) -> CommandReply | None:
        if isinstance(cmd, MissionUpload):
            if f.mode == M.MISSION:
                return refuse(f.vid, RejectCode.DENIED, "a mission is flying")
            f.items = [self.enu(i) for i in cmd.items]
            f.index, f.reached, f.finished = (0 if f.items else -1), 0, False
        elif isinstance(cmd, MissionClear):
            f.items, f.index, f.reached, f.finished = [], -1, 0, False
        elif isinstance(cmd, MissionDownload):
            return CommandReply(vehicle_id=f.vid, accepted=True, mission=list(f.items))
        elif isinstance(cmd, MissionStart) or (isinstance(cmd, SetMode) and cmd.mode == M.MISSION):
            return self._start_mission(f, cmd)
        else:
            return None
        return CommandReply(vehicle_id=f.vid, accepted=True)

    def _start_mission(self, f: Fake, cmd: MissionStart | SetMode) -> CommandReply:
        if f.mode == M.DISARMED:
            return refuse(f.vid, RejectCode.DENIED, "disarmed: arm before starting a mission")
        if not f.items:
            return refuse(f.vid, RejectCode.DENIED, "no mission uploaded")
        if isinstance(cmd, MissionStart):
            f.index, f.reached, f.finished = cmd.start_index, 0, False
        first = f.items[f.index]
        if f.mode == M.ARMED and first.command != MissionCommand.TAKEOFF:
            f.climb_to = max(first.z, f.home[2] + f.params["MIS_TAKEOFF_ALT"])
        f.mode, f.descending = M.MISSION, False
        return CommandReply(vehicle_id=f.vid, accepted=True)

    def _flight(self, f: Fake, cmd: Command) -> CommandReply | None:
        """Mode changes in the air: land, return, hold, go to."""
        mode = cmd.mode if isinstance(cmd, SetMode) else None
        here = (f.pos[0], f.pos[1], f.pos[2])
        if f.mode not in AIRBORNE:
            return refuse(f.vid, RejectCode.DENIED, "not flying")
        if isinstance(cmd, Land) or mode == M.LAND:
            f.mode, f.target = M.LAND, here
        elif isinstance(cmd, ReturnToLaunch) or mode == M.RTL:
            f.mode, f.descending = M.RTL, False
        elif isinstance(cmd, Hold | MissionPause) or mode == M.HOLD:
            f.mode, f.target = M.HOLD, here
        elif isinstance(cmd, Goto):
            f.mode, f.target = M.HOLD, cmd.position_enu_m
        else:
            return None
        return CommandReply(vehicle_id=f.vid, accepted=True)

    def enu(self, item: MissionItem) -> MissionItem:
        if item.frame == MissionFrame.ENU:
            return item
        e, n, u = pymap3d.geodetic2enu(
            item.x, item.y, item.z, self.origin.lat_deg, self.origin.lon_deg, self.origin.alt_m
        )
        return MissionItem(
            command=item.command,
            x=float(e),
            y=float(n),
            z=float(u),
            acceptance_radius_m=item.acceptance_radius_m,
        )

    # ------------------------------------------------------------------ motion
    def _move(self, f: Fake, goal: tuple[float, float, float]) -> float:
        dx, dy, dz = (goal[i] - f.pos[i] for i in range(3))
        dxy = math.hypot(dx, dy)
        sxy = min(XY_SPEED * DT, dxy)
        sz = max(-Z_SPEED * DT, min(Z_SPEED * DT, dz))
        vx = (dx / dxy * sxy / DT) if dxy > 1e-9 else 0.0
        vy = (dy / dxy * sxy / DT) if dxy > 1e-9 else 0.0
        f.vel = (vx, vy, sz / DT)
        f.pos[0] += vx * DT
        f.pos[1] += vy * DT
        f.pos[2] = max(f.home[2], f.pos[2] + sz)
        return math.dist(f.pos, goal)

    def _descend(self, f: Fake, x: float, y: float) -> bool:
        self._move(f, (x, y, f.home[2]))
        return f.pos[2] <= f.home[2] + 1e-6

    def step(self, f: Fake) -> None:
        if f.mode in (M.DISARMED, M.ARMED):
            f.vel = (0.0, 0.0, 0.0)
            return
        if f.mode == M.TAKEOFF:
            if self._move(f, f.target) < 0.05:
                f.mode = M.HOLD
        elif f.mode == M.HOLD:
            self._move(f, f.target)
        elif f.mode == M.LAND:
            if self._descend(f, f.target[0], f.target[1]):
                f.mode = M.DISARMED
        elif f.mode == M.RTL:
            self._return(f)
        elif f.mode == M.MISSION:
            self._fly_mission(f)

    def _return(self, f: Fake) -> None:
        """RTL: climb to the return altitude on the way home, then land there."""
        alt = f.home[2] + f.params["RTL_RETURN_ALT"]
        if not f.descending:
            if self._move(f, (f.home[0], f.home[1], max(alt, f.pos[2]))) < 0.5:
                f.descending = True
        elif self._descend(f, f.home[0], f.home[1]):
            f.mode = M.DISARMED

    def _fly_mission(self, f: Fake) -> None:
        if f.climb_to is not None:
            if self._move(f, (f.pos[0], f.pos[1], f.climb_to)) < 0.3:
                f.climb_to = None
            return
        item = f.items[f.index]
        if item.command == MissionCommand.LAND:
            if self._descend(f, item.x, item.y):
                f.reached, f.finished, f.mode = f.reached + 1, True, M.DISARMED
            return
        goal = (
            (f.pos[0], f.pos[1], item.z)
            if item.command == MissionCommand.TAKEOFF
            else (item.x, item.y, item.z)
        )
        if self._move(f, goal) <= min(item.acceptance_radius_m, 0.5):
            f.reached += 1
            if f.index + 1 >= len(f.items):
                f.finished, f.mode, f.target = True, M.HOLD, goal
            else:
                f.index += 1

    # ------------------------------------------------------------------ messages
    def state(self, f: Fake, tick: int) -> VehicleState:
        lat, lon, alt = pymap3d.enu2geodetic(
            f.pos[0],
            f.pos[1],
            f.pos[2],
            self.origin.lat_deg,
            self.origin.lon_deg,
            self.origin.alt_m,
        )
        return VehicleState(
            vehicle_id=f.vid,
            tick=tick,
            sim_time_s=self.t,
            position_enu_m=(f.pos[0], f.pos[1], f.pos[2]),
            velocity_enu_m_s=f.vel,
            attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
            body_rates_rad_s=(0.0, 0.0, 0.0),
            lat_deg=float(lat),
            lon_deg=float(lon),
            alt_m=float(alt),
            on_ground=f.on_ground,
        )

    def status(self, f: Fake) -> VehicleStatus:
        return VehicleStatus(
            vehicle_id=f.vid,
            sim_time_s=self.t,
            mode=f.mode,
            armed=f.mode != M.DISARMED,
            landed=f.on_ground,
            mission_index=f.index,
            mission_count=len(f.items),
            mission_items_reached=f.reached,
            mission_finished=f.finished,
            home_enu_m=f.home,
        )


class FakeAutopilot:
    """One vehicle's autopilot on the bus: its status publisher, then (:meth:`serve`) its
    ``vehicle/<id>/cmd`` queryable and its liveliness token ``autopilot-<id>``.

    Commands come decoded through ``swarmbus.reqrep`` (one that does not decode is refused with
    an ``ErrorReply`` there); ``on_command`` answers each on Zenoh's thread with a
    ``CommandReply``, or with None for no reply at all."""

    def __init__(self, session: zenoh.Session, keys: Keys, vid: str) -> None:
        self.session = session
        self.keys = keys
        self.vid = vid
        self.status_pub = session.declare_publisher(keys.vehicle_status(vid))
        self._declared: list[Any] = []

    def serve(self, on_command: Callable[[Command], CommandReply | None]) -> None:
        """Take commands (answered by ``on_command``), then say the autopilot is alive."""

        def answer(incoming: Incoming[Command]) -> None:
            reply = on_command(incoming.request)
            if reply is None:
                incoming.drop()  # the client sees no reply
            else:
                incoming.reply(reply)

        key, token = self.keys.vehicle_cmd(self.vid), self.keys.node_health(f"autopilot-{self.vid}")
        commands = serve_later(self.session, key, Command, answer)  # type: ignore[arg-type]
        self._declared += [commands, self.session.liveliness().declare_token(token)]

    def publish_status(self, status: VehicleStatus) -> None:
        self.status_pub.put(encode(status))

    def close(self) -> None:
        """Undeclare the token, then the queryable."""
        for declared in reversed(self._declared):
            declared.undeclare()
        self._declared.clear()


def command_handler(
    world: World, f: Fake, autopilot: FakeAutopilot
) -> Callable[[Command], CommandReply]:
    """``f``'s commands under the world's rules: handle, publish the status, then reply."""

    def handle(cmd: Command) -> CommandReply:
        with world.lock:
            reply = world.handle(f, cmd)
            status = world.status(f)
        autopilot.publish_status(status)  # as the autopilot: status, then reply
        return reply

    return handle


Pubs = dict[str, tuple[Any, Any, Any]]  # vehicle → (state, status, concentration) publishers


def vehicle_messages(
    world: World, f: Fake, tick: int, pubs: Pubs, last_status: dict[str, tuple[object, ...]]
) -> tuple[VehicleState, list[tuple[Any, bytes]]]:
    """One tick of ``f``: its state, its status when it changed (or each 60 ticks), a reading."""
    st_pub, status_pub, conc_pub = pubs[f.vid]
    state = world.state(f, tick)
    out: list[tuple[Any, bytes]] = [(st_pub, encode(state))]
    status = world.status(f)
    key = (
        status.mode,
        status.armed,
        status.landed,
        status.mission_index,
        status.mission_count,
        status.mission_items_reached,
        status.mission_finished,
        status.home_enu_m,
    )
    if last_status.get(f.vid) != key or tick % 60 == 0:
        last_status[f.vid] = key
        out.append((status_pub, encode(status)))
    if tick % 12 == 0:
        value = round(0.01 * (1 + math.sin(world.t)), 6)
        reading = ConcentrationReading(
            vehicle_id=f.vid,
            sim_time_s=world.t,
            position_enu_m=(f.pos[0], f.pos[1], f.pos[2]),
            available=True,
            reported_g_m3=value,
            true_g_m3=value,
        )
        out.append((conc_pub, encode(reading)))
    return state, out


def run(world: World, speed: float, pubs: Pubs, tick_pub: Any) -> None:
    """Step every vehicle at ``speed`` × real time and publish, until interrupted."""
    start = time.monotonic()
    tick = 0
    last_status: dict[str, tuple[object, ...]] = {}
    while True:
        wall = time.monotonic() - start
        if world.t > wall * speed:
            time.sleep(min(0.01, world.t / speed - wall))
            continue
        out: list[tuple[Any, bytes]] = []
        states: list[VehicleState] = []
        with world.lock:  # step under the lock, publish outside it
            tick += 1
            world.t = tick * DT
            for f in world.vehicles.values():
                world.step(f)
                state, messages = vehicle_messages(world, f, tick, pubs, last_status)
                states.append(state)
                out += messages
            # as the physics: every state in one tick (the gateway reads these)
            tick_msg = SimTick(tick=tick, sim_time_s=world.t, control_dt_s=DT, states=states)
            out.insert(0, (tick_pub, encode(tick_msg)))
        for pub, payload in out:
            pub.put(payload)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--connect", required=True)
    ap.add_argument("--scenario", required=True)
    ap.add_argument("--speed", type=float, default=2.0)
    ap.add_argument("--skip", action="append", default=[], help="vehicle the test plays itself")
    args = ap.parse_args()
    scenario = load_scenario(args.scenario)
    keys = Keys(scenario.world.name)
    world = World(scenario)
    for vid in args.skip:
        world.vehicles.pop(vid, None)
    net = NetworkConfig(connect=[args.connect], listen=["tcp/127.0.0.1:0"])
    with open_session(net) as session:
        autopilots = {vid: FakeAutopilot(session, keys, vid) for vid in world.vehicles}
        pubs: Pubs = {
            vid: (
                session.declare_publisher(keys.vehicle_state(vid)),
                autopilot.status_pub,
                session.declare_publisher(keys.vehicle_concentration(vid)),
            )
            for vid, autopilot in autopilots.items()
        }
        for vid, autopilot in autopilots.items():
            autopilot.serve(command_handler(world, world.vehicles[vid], autopilot))
        try:
            run(world, args.speed, pubs, session.declare_publisher(keys.tick()))
        except KeyboardInterrupt:
            pass
        finally:
            for autopilot in autopilots.values():
                autopilot.close()


if __name__ == "__main__":
    main()
