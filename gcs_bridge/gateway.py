"""``plumeswarm node gateway``: the MAVLink 2 gateway between ground stations and the bus.

Every vehicle of the scenario is one MAVLink system (its sysid, component 1, PX4 conventions),
reachable on the shared GCS link and on its own API link. The gateway talks to autopilots only
over the bus contract: it subscribes ``vehicle/*/{state,status,concentration}`` and sends
``Command`` queries to ``vehicle/<id>/cmd``, answering MAVLink with the autopilot's real result.

One thread runs the loop (UDP sockets + a self-pipe woken by Zenoh callbacks), so MAVLink
encoding, sequence numbers and per-vehicle protocol state never race.
"""

from __future__ import annotations

import contextlib
import logging
import math
import select
import threading
import time
from collections.abc import Callable
from types import TracebackType
from typing import Any

import zenoh

from gcs_bridge import mission as ms
from gcs_bridge.bus import (
    KIND_READING,
    KIND_STATE,
    KIND_STATUS,
    Commander,
    Inbox,
    Waker,
    subscribe_vehicles,
)
from gcs_bridge.commands import (
    ACCEPTED,
    DENIED,
    TEMPORARILY_REJECTED,
    UNSUPPORTED,
    CommandRequest,
    Facts,
    Translation,
    refuse,
    result_of_reply,
    translate,
    translate_mode,
)
from gcs_bridge.dialect import (
    MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    MAV_CMD_REQUEST_PROTOCOL_VERSION,
    MAVLINK_MSG_ID_PROTOCOL_VERSION,
    Msg,
    mavlink,
    protocol_version_message,
)
from gcs_bridge.frames import ned_to_enu
from gcs_bridge.links import Link
from gcs_bridge.modes import decode_custom_mode
from gcs_bridge.options import GatewayOptions, OptionError, parse_options
from gcs_bridge.params import ParamError
from gcs_bridge.telemetry import BUILDERS, ID_MISSION_CURRENT, StreamSchedule, wind_enu
from gcs_bridge.vehicle import ArmIntent, Vehicle
from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    Command,
    CommandReply,
    ConcentrationReading,
    Disarm,
    FlightMode,
    GcsHeartbeat,
    GetParams,
    Hold,
    MissionClear,
    MissionDownload,
    MissionStart,
    MissionUpload,
    RejectCode,
    SetMode,
    SetParam,
    Setpoint,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import Scenario
from swarmbus.session import Presence

log = logging.getLogger(__name__)

TICK_S = 0.1  # wall-clock housekeeping: heartbeats, transfer timeouts, parameter sync
ALIVE_WITHOUT_TOKEN_S = 3.0
GCS_HEARTBEAT_FORWARD_S = 0.5
GCS_LINK_TIMEOUT_S = 3.0  # wall: a GCS silent this long is gone (QGC's own is ~3.5 s)
PARAM_SYNC_RETRY_S = 5.0
STATUSTEXT_MAX = 50

_MISSION_RESULT_OF_CODE = {
    RejectCode.DENIED: ms.Result.DENIED,
    RejectCode.INVALID: ms.Result.INVALID,
    RejectCode.UNSUPPORTED: ms.Result.UNSUPPORTED,
}

Handler = Callable[[Link, Vehicle, Msg, ms.Peer, float], None]
Done = Callable[[CommandReply], None]


def _text(value: Any) -> str:
    if isinstance(value, bytes | bytearray):
        return bytes(value).split(b"\0", 1)[0].decode("ascii", "replace")
    return str(value).split("\0", 1)[0]


class Gateway:
    """All vehicles' MAVLink systems, their links, and the bus plumbing behind them."""

    def __init__(
        self,
        scenario: Scenario,
        options: GatewayOptions,
        vehicle_ids: list[str],
        session: zenoh.Session | None,
        keys: Keys,
    ) -> None:
        self.options = options
        self.keys = keys
        wind = wind_enu(scenario.wind.speed_m_s, scenario.wind.from_deg)
        index_of = {v.id: i for i, v in enumerate(scenario.vehicles)}
        self.vehicles = {vid: Vehicle(scenario, vid, index_of[vid], wind) for vid in vehicle_ids}
        self.by_sysid = {v.sysid: v for v in self.vehicles.values()}
        self.waker = Waker()
        self.inbox = Inbox(self.waker)
        self.links: dict[str, Link] = {}
        self.links_of: dict[int, list[Link]] = {v.sysid: [] for v in self.vehicles.values()}
        self.schedules: dict[tuple[str, int], StreamSchedule] = {}
        try:
            self._open_links()
        except OSError:
            self._close_links()
            raise
        self._session = session
        self._commanders: dict[str, Commander] = {}
        self._subs: list[Any] = []
        self._presence: Presence | None = None
        if session is not None:
            for v in self.vehicles.values():
                self._commanders[v.id] = Commander(
                    session, keys.vehicle_cmd(v.id), v.id, options.cmd_timeout_s, self.inbox
                )
            self._presence = Presence(session, keys)
            self._subs = subscribe_vehicles(session, keys, set(self.vehicles), self.inbox)
        self._inflight: set[tuple[int, int, int, int]] = set()
        self._param_sync: dict[str, float] = {}  # vehicle id → next attempt (wall s); -1 busy
        self._next_heartbeat_s = 0.0
        self._next_tick_s = 0.0
        self._handlers: dict[str, Handler] = {
            "COMMAND_LONG": self._on_command,
            "COMMAND_INT": self._on_command,
            "SET_MODE": self._on_set_mode,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            "MISSION_COUNT": self._on_mission_count,
            "MISSION_ITEM_INT": self._on_mission_item,
            "MISSION_ITEM": self._on_mission_item,
            "MISSION_ACK": self._on_mission_ack,
            "MISSION_REQUEST_LIST": self._on_mission_request_list,
            "MISSION_REQUEST_INT": self._on_mission_request,
            "MISSION_REQUEST": self._on_mission_request,
            "MISSION_CLEAR_ALL": self._on_mission_clear_all,
            "MISSION_SET_CURRENT": self._on_mission_set_current,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_position_target,
        }
        self._local_commands: dict[
            int, Callable[[Link, Vehicle, CommandRequest, ms.Peer, float], None]
        ] = {
            int(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL): self._cmd_set_message_interval,
            int(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL): self._cmd_get_message_interval,
            int(mavlink.MAV_CMD_REQUEST_MESSAGE): self._cmd_request_message,
            MAV_CMD_REQUEST_PROTOCOL_VERSION: self._cmd_request_protocol_version,
            MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_autopilot_version,
        }

    # ------------------------------------------------------------------ set-up / tear-down
    def _open_links(self) -> None:
        o = self.options
        sysids = [v.sysid for v in self.vehicles.values()]
        gcs = Link(
            "gcs",
            (o.bind_host, o.gcs_bind_port),
            (o.host, o.gcs_port),
            sysids,
            o.signing_key_for("gcs"),
            link_id=0,
        )
        self._add_link(gcs)
        if not o.api_links:
            return
        for v in self.vehicles.values():
            bind_port = o.api_bind_port_base + v.index if o.api_bind_port_base else 0
            link = Link(
                f"api-{v.id}",
                (o.bind_host, bind_port),
                (o.host, o.api_port_base + v.index),
                [v.sysid],
                o.signing_key_for("api"),
                link_id=(v.index + 1) % 256,
            )
            self._add_link(link)

    def _add_link(self, link: Link) -> None:
        self.links[link.name] = link
        for sysid in link.sysids:
            self.links_of[sysid].append(link)
            self.schedules[(link.name, sysid)] = StreamSchedule(self.options.rates_hz)
        log.info(
            "link %s: %s:%d → %s (sysids %s, signing %s)",
            link.name,
            *link.address,
            link.default_peer,
            link.sysids,
            "on" if link.signing else "off",
        )

    def _close_links(self) -> None:
        for link in self.links.values():
            link.close()

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(zenoh.ZError):
                sub.undeclare()
        if self._presence is not None:
            with contextlib.suppress(zenoh.ZError):
                self._presence.close()
        self._close_links()
        self.waker.close()

    def __enter__(self) -> Gateway:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ the loop
    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self.poll(0.2)

    def poll(self, max_wait_s: float) -> None:
        """Wait for traffic (at most ``max_wait_s``), handle all of it, do due housekeeping."""
        now = time.monotonic()
        timeout = max(0.0, min(max_wait_s, self._next_tick_s - now))
        sources: list[Any] = [self.waker, *self.links.values()]
        ready, _, _ = select.select(sources, [], [], timeout)
        now = time.monotonic()
        for source in ready:
            if source is self.waker:
                self.waker.drain()
            else:
                for msg, addr in source.receive(now):
                    self._dispatch(source, msg, addr, now)
        self._drain_inbox(now)
        if now >= self._next_tick_s:
            self._next_tick_s = now + TICK_S
            self._tick(now)

    def _dispatch(self, link: Link, msg: Msg, addr: tuple[str, int], now: float) -> None:
        try:
            self._handle(link, msg, addr, now)
        except Exception:  # a hostile frame must never end the gateway
            log.exception("%s: error handling %s", link.name, msg.get_type())

    def _drain_inbox(self, now: float) -> None:
        latest, calls = self.inbox.take()
        # Status first (telemetry for a state carries the newest status), and bus data before
        # command completions: the autopilot publishes its status before it replies, so an
        # ACK never goes out while the gateway still holds the status from before the command.
        for kind in (KIND_STATUS, KIND_READING, KIND_STATE):
            for (k, vid), payload in latest.items():
                if k == kind:
                    try:
                        self._on_bus(kind, self.vehicles[vid], payload, now)
                    except Exception:
                        log.exception("error handling %s of %s", kind, vid)
        for call in calls:
            try:
                call()
            except Exception:
                log.exception("error in a command completion")

    def _tick(self, now: float) -> None:
        if now >= self._next_heartbeat_s:
            period = self.options.heartbeat_period_s
            late = now - self._next_heartbeat_s > period
            self._next_heartbeat_s = now + period if late else self._next_heartbeat_s + period
            for v in self.vehicles.values():
                if self.alive(v, now):
                    self._send_all(v, v.heartbeat(), now)
        for v in self.vehicles.values():
            if v.uploader.active:
                self._run_mission_actions(v, v.uploader.on_timer(now), now)
            self._maybe_sync_params(v, now)

    # ------------------------------------------------------------------ presence
    def alive(self, v: Vehicle, now: float) -> bool:
        """Is the vehicle's autopilot there (token, or a status lately)? Only then does it exist."""
        if now - v.last_status_wall_s < ALIVE_WITHOUT_TOKEN_S:
            return True
        return self._presence is not None and f"autopilot-{v.id}" in self._presence.alive

    # ------------------------------------------------------------------ sending
    def _send_all(self, v: Vehicle, msg: Msg, now: float) -> None:
        for link in self.links_of[v.sysid]:
            link.send(v.sysid, msg, now)

    def _send(self, link: Link, v: Vehicle, msg: Msg, now: float) -> None:
        link.send(v.sysid, msg, now)

    def _statustext(self, link: Link | None, v: Vehicle, text: str, now: float) -> None:
        msg = mavlink.MAVLink_statustext_message(
            mavlink.MAV_SEVERITY_WARNING, text[:STATUSTEXT_MAX].encode("ascii", "replace")
        )
        if link is None:
            self._send_all(v, msg, now)
        else:
            self._send(link, v, msg, now)

    def _ack(
        self,
        link: Link,
        v: Vehicle,
        command: int,
        result: int,
        peer: ms.Peer,
        now: float,
        reason: str = "",
    ) -> None:
        ack = mavlink.MAVLink_command_ack_message(
            command, result, 0, 0, peer.system, peer.component
        )
        self._send(link, v, ack, now)
        if result != ACCEPTED and reason:
            self._statustext(link, v, f"{v.id}: {reason}", now)

    def _submit(self, v: Vehicle, command: Command, done: Callable[[CommandReply], None]) -> None:
        commander = self._commanders.get(v.id)
        if commander is None:
            done(
                CommandReply(
                    vehicle_id=v.id, accepted=False, code=RejectCode.FAILED, reason="no bus"
                )
            )
            return
        commander.submit(command, done)

    # ------------------------------------------------------------------ bus data
    def _on_bus(self, kind: str, v: Vehicle, payload: bytes, now: float) -> None:
        try:
            if kind == KIND_STATE:
                state = decode(payload, VehicleState)
                if state.vehicle_id == v.id:
                    self._on_state(v, state, now)
            elif kind == KIND_STATUS:
                status = decode(payload, VehicleStatus)
                if status.vehicle_id == v.id:
                    self._on_status(v, status, now)
            else:
                reading = decode(payload, ConcentrationReading)
                if reading.vehicle_id == v.id:
                    v.reading = reading
        except MessageError as exc:
            log.warning("%s of %s: %s", kind, v.id, exc)

    def _on_state(self, v: Vehicle, state: VehicleState, now: float) -> None:
        if v.state is not None and state.sim_time_s < v.state.sim_time_s:
            v.last_gcs_heartbeat_sim_s = -1e9  # a new simulation
        v.state = state
        if not self.alive(v, now):
            return
        self._keep_gcs_link_alive(v, now)
        built: dict[int, Msg | None] = {}
        view = None
        for link in self.links_of[v.sysid]:
            for msg_id in self.schedules[(link.name, v.sysid)].due(state.sim_time_s):
                if msg_id not in built:
                    if msg_id == ID_MISSION_CURRENT:
                        built[msg_id] = v.mission_current_msg()
                    else:
                        view = view or v.view()
                        built[msg_id] = BUILDERS[msg_id](view)
                msg = built[msg_id]
                if msg is not None:
                    link.send(v.sysid, msg, now)

    def _on_status(self, v: Vehicle, status: VehicleStatus, now: float) -> None:
        ev = v.update_status(status, now)
        if ev.heartbeat:
            self._send_all(v, v.heartbeat(), now)
        for seq in ev.reached_seqs:
            self._send_all(v, mavlink.MAVLink_mission_item_reached_message(seq), now)
        if ev.mission_current:
            self._send_all(v, v.mission_current_msg(), now)
        if ev.home_changed:
            home = BUILDERS[mavlink.MAVLINK_MSG_ID_HOME_POSITION](v.view())
            if home is not None:
                self._send_all(v, home, now)
        self._maybe_sync_params(v, now)

    # ------------------------------------------------------------------ MAVLink in
    def _handle(self, link: Link, msg: Msg, addr: tuple[str, int], now: float) -> None:
        kind = msg.get_type()
        src = int(msg.get_srcSystem())
        if src in self.by_sysid:
            return  # one of our own vehicles echoed back (a forwarding client): never a GCS
        peer = ms.Peer(link.name, addr, src, int(msg.get_srcComponent()))
        if kind == "HEARTBEAT":
            self._on_gcs_heartbeat(link, now)
            return
        handler = self._handlers.get(kind)
        if handler is None:
            return
        for v in self._targets(link, msg):
            handler(link, v, msg, peer, now)

    def _targets(self, link: Link, msg: Msg) -> list[Vehicle]:
        """Vehicles of ``link`` a message is addressed to; others ignore it (QGC's UDP link
        writes every packet to every vehicle it heard)."""
        system = getattr(msg, "target_system", None)
        component = getattr(msg, "target_component", 0)
        if system is None or component not in (0, 1):
            return []
        if system == 0:
            return [self.by_sysid[s] for s in link.sysids]
        if system in link.sysids:
            return [self.by_sysid[system]]
        return []

    def _on_gcs_heartbeat(self, link: Link, now: float) -> None:
        """A ground station is there: tell each vehicle (its data-link-loss failsafe)."""
        link.gcs_heard_s = now
        for sysid in link.sysids:
            v = self.by_sysid[sysid]
            if now - v.last_gcs_heartbeat_s >= GCS_HEARTBEAT_FORWARD_S:
                self._forward_gcs_heartbeat(v, now)

    def _forward_gcs_heartbeat(self, v: Vehicle, now: float) -> None:
        if not self.alive(v, now):
            return
        v.last_gcs_heartbeat_s = now
        if v.state is not None:
            v.last_gcs_heartbeat_sim_s = v.state.sim_time_s
        self._submit(v, GcsHeartbeat(source="mavlink"), lambda reply: None)

    def _keep_gcs_link_alive(self, v: Vehicle, now: float) -> None:
        """The GCS beats once per wall second, the autopilot's link timeout is in sim seconds,
        and the simulation may run many times faster than real time. So while a GCS was heard
        within GCS_LINK_TIMEOUT_S (wall), its heartbeat is repeated once per sim second; when it
        falls silent the repeats stop and the autopilot's own timeout runs in sim time."""
        if v.state is None or v.state.sim_time_s - v.last_gcs_heartbeat_sim_s < 1.0:
            return
        if any(now - link.gcs_heard_s <= GCS_LINK_TIMEOUT_S for link in self.links_of[v.sysid]):
            self._forward_gcs_heartbeat(v, now)

    # ------------------------------------------------------------------ commands
    def _facts(self, v: Vehicle) -> Facts:
        return Facts(
            origin=v.origin,
            home_amsl_m=v.home_amsl_m,
            home_enu=v.home_enu,
            position_enu=v.state.position_enu_m if v.state is not None else None,
            landed=v.status.landed if v.status is not None else True,
            takeoff_alt_m=v.params.value("MIS_TAKEOFF_ALT"),
            mission_seqs=v.seqs(),
            cruise_m_s=v.params.value("MPC_XY_CRUISE"),
        )

    def _select_while_disarmed(self, v: Vehicle, command: Command) -> Translation | None:
        """PX4 lets a GCS pick takeoff or mission mode while disarmed and fly it on arming
        (QGC's takeoff and start-mission flows). Our autopilot takes those only once armed,
        so the gateway keeps the selection and sends it right after a successful arm."""
        if v.status is None or v.armed:
            return None
        if isinstance(command, Takeoff) or (
            isinstance(command, SetMode) and command.mode == FlightMode.MISSION
        ):
            why = v.armable()
            if why is not None:
                return refuse(TEMPORARILY_REJECTED, f"cannot select a mode to arm in: {why}")
            if isinstance(command, Takeoff):
                v.intent = ArmIntent(FlightMode.TAKEOFF, command.altitude_m)
            elif v.status.mission_count == 0:
                return refuse(TEMPORARILY_REJECTED, "no mission uploaded")
            else:
                v.intent = ArmIntent(FlightMode.MISSION)
            return Translation()
        if isinstance(command, Hold):
            v.intent = None
            return Translation()
        return None

    def _arm_then_intent(self, v: Vehicle, intent: ArmIntent, done: Done) -> Done:
        """Completion of an Arm that carries a selected mode: on success, fly the mode."""

        def armed(reply: CommandReply) -> None:
            done(reply)
            if not reply.accepted:
                return
            follow: Command = (
                Takeoff(altitude_m=intent.altitude_m)
                if intent.mode == FlightMode.TAKEOFF
                else SetMode(mode=FlightMode.MISSION)
            )

            def flown(r: CommandReply) -> None:
                if not r.accepted:
                    self._statustext(
                        None, v, f"{v.id}: {intent.mode} refused: {r.reason}", time.monotonic()
                    )
                    self._send_all(v, v.heartbeat(), time.monotonic())

            self._submit(v, follow, flown)

        return armed

    def _on_command(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        if msg.get_type() == "COMMAND_LONG":
            req = CommandRequest.from_long(msg)
        else:
            req = CommandRequest.from_int(msg)
        key = (v.sysid, peer.system, peer.component, req.command)
        if key in self._inflight:
            return  # a client's retry of a command still waiting for the autopilot
        local = self._local_commands.get(req.command)
        if local is not None:
            local(link, v, req, peer, now)
            return
        t = translate(req, self._facts(v))
        if t is None:
            self._ack(link, v, req.command, UNSUPPORTED, peer, now)
            return
        if t.bus is not None:
            t = self._select_while_disarmed(v, t.bus) or t
            if t.bus is None and t.result == ACCEPTED:
                self._send_all(v, v.heartbeat(), now)
        if t.bus is None:
            self._ack(link, v, req.command, t.result, peer, now, t.reason)
            return
        self._inflight.add(key)

        def done(reply: CommandReply) -> None:
            self._inflight.discard(key)
            done_now = time.monotonic()
            self._ack(link, v, req.command, result_of_reply(reply), peer, done_now, reply.reason)

        completion: Done = done
        if isinstance(t.bus, Disarm):
            v.intent = None
        elif isinstance(t.bus, Arm) and v.intent is not None:
            intent, v.intent = v.intent, None
            completion = self._arm_then_intent(v, intent, done)
        self._submit(v, t.bus, completion)

    def _cmd_set_message_interval(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        schedule = self.schedules[(link.name, v.sysid)]
        ok = math.isfinite(req.param1) and schedule.set_interval_us(int(req.param1), req.param2)
        self._ack(link, v, req.command, ACCEPTED if ok else DENIED, peer, now)

    def _cmd_get_message_interval(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        if not math.isfinite(req.param1):
            self._ack(link, v, req.command, DENIED, peer, now)
            return
        msg_id = int(req.param1)
        interval = self.schedules[(link.name, v.sysid)].interval_us(msg_id)
        self._ack(link, v, req.command, ACCEPTED, peer, now)
        self._send(link, v, mavlink.MAVLink_message_interval_message(msg_id, interval), now)

    def _requested_message(self, v: Vehicle, msg_id: int) -> Msg | None:
        if msg_id == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return v.autopilot_version()
        if msg_id == MAVLINK_MSG_ID_PROTOCOL_VERSION:
            return protocol_version_message()
        if msg_id == mavlink.MAVLINK_MSG_ID_HEARTBEAT:
            return v.heartbeat()
        if msg_id == ID_MISSION_CURRENT:
            return v.mission_current_msg()
        builder = BUILDERS.get(msg_id)
        return builder(v.view()) if builder is not None else None

    def _cmd_request_message(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        msg_id = int(req.param1) if math.isfinite(req.param1) else -1
        known = msg_id in BUILDERS or msg_id in (
            mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
            MAVLINK_MSG_ID_PROTOCOL_VERSION,
            mavlink.MAVLINK_MSG_ID_HEARTBEAT,
            ID_MISSION_CURRENT,
        )
        if not known:  # AVAILABLE_MODES, COMPONENT_METADATA/INFORMATION, ...
            self._ack(link, v, req.command, UNSUPPORTED, peer, now)
            return
        msg = self._requested_message(v, msg_id)
        if msg is None:  # e.g. HOME_POSITION before the autopilot reported one
            self._ack(link, v, req.command, TEMPORARILY_REJECTED, peer, now)
            return
        self._ack(link, v, req.command, ACCEPTED, peer, now)
        self._send(link, v, msg, now)

    def _cmd_request_protocol_version(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        self._ack(link, v, req.command, ACCEPTED, peer, now)
        self._send(link, v, protocol_version_message(), now)

    def _cmd_request_autopilot_version(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        self._ack(link, v, req.command, ACCEPTED, peer, now)
        self._send(link, v, v.autopilot_version(), now)

    def _on_set_mode(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        """SET_MODE has no ACK: the client watches the heartbeat's custom_mode change."""
        mode = decode_custom_mode(int(msg.custom_mode))
        t = translate_mode(float(msg.base_mode), mode.main, mode.sub, self._facts(v))
        if t.bus is not None:
            t = self._select_while_disarmed(v, t.bus) or t
        if t.bus is None:
            if t.result == ACCEPTED:
                self._send_all(v, v.heartbeat(), now)
            else:
                self._statustext(link, v, f"{v.id}: {t.reason}", now)
            return

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if not reply.accepted:
                self._statustext(link, v, f"{v.id}: mode change refused: {reply.reason}", done_now)
            self._send_all(v, v.heartbeat(), done_now)

        self._submit(v, t.bus, done)

    def _on_position_target(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        """Offboard setpoints (local NED, world origin) → ``Setpoint``; no ACK in MAVLink."""
        if int(msg.coordinate_frame) != mavlink.MAV_FRAME_LOCAL_NED:
            return
        mask = int(msg.type_mask)
        pos = (float(msg.x), float(msg.y), float(msg.z))
        vel = (float(msg.vx), float(msg.vy), float(msg.vz))
        use_pos = not mask & 0b111 and all(map(math.isfinite, pos))
        use_vel = not mask & 0b111000 and all(map(math.isfinite, vel))
        yaw = float(msg.yaw)
        yaw_deg = None
        if not mask & 1024 and math.isfinite(yaw):
            yaw_deg = (90.0 - math.degrees(yaw) + 180.0) % 360.0 - 180.0
        if not (use_pos or use_vel):
            return
        try:
            setpoint = Setpoint(
                position_enu_m=ned_to_enu(pos) if use_pos else None,
                velocity_enu_m_s=ned_to_enu(vel) if use_vel and not use_pos else None,
                yaw_deg=yaw_deg,
            )
        except (TypeError, ValueError) as exc:
            log.debug("%s: unusable setpoint: %s", v.id, exc)
            return
        self._submit(v, setpoint, lambda reply: None)

    # ------------------------------------------------------------------ parameters
    def _param_value(self, link: Link, v: Vehicle, name: str, now: float) -> None:
        index = v.params.index_of(name)
        spec = v.params.spec(name)
        if index is None or spec is None:
            return
        msg = mavlink.MAVLink_param_value_message(
            name.encode("ascii"), v.params.wire_value(name), spec.param_type, v.params.count, index
        )
        self._send(link, v, msg, now)

    def _on_param_request_list(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        for spec in v.params.specs:
            self._param_value(link, v, spec.name, now)

    def _on_param_request_read(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        index = int(msg.param_index)
        if index >= 0:
            if index < v.params.count:
                self._param_value(link, v, v.params.specs[index].name, now)
            return
        self._param_value(link, v, _text(msg.param_id), now)

    def _on_param_set(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        name = _text(msg.param_id)
        spec = v.params.spec(name)
        if spec is None:
            log.info("%s: PARAM_SET of unknown parameter %r ignored", v.id, name)
            return
        try:
            value = v.params.decode_set(name, float(msg.param_value))
        except ParamError as exc:
            self._statustext(link, v, f"{v.id}: {exc}", now)
            self._param_value(link, v, name, now)  # the unchanged value says "refused"
            return

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if reply.accepted:
                confirmed = (reply.params or {}).get(name, value)
                v.params.set(name, confirmed, backed=True)
            elif reply.code == RejectCode.UNSUPPORTED and spec.gateway_side:
                v.params.set(name, value, backed=False)
            else:
                self._statustext(link, v, f"{v.id}: {name} refused: {reply.reason}", done_now)
            self._param_value(link, v, name, done_now)

        self._submit(v, SetParam(name=name, value=value), done)

    def _maybe_sync_params(self, v: Vehicle, now: float) -> None:
        """Once the autopilot is there, take its parameter values (GetParams)."""
        if v.params_synced or v.status is None:
            return
        next_try = self._param_sync.get(v.id, 0.0)
        if next_try < 0 or now < next_try:
            return
        self._param_sync[v.id] = -1.0

        def done(reply: CommandReply) -> None:
            if reply.accepted and reply.params is not None:
                v.params.merge_from_autopilot(reply.params)
                v.params_synced = True
            elif reply.code == RejectCode.UNSUPPORTED:
                log.info("%s: autopilot has no parameters; the gateway keeps its own", v.id)
                v.params_synced = True
            else:
                self._param_sync[v.id] = time.monotonic() + PARAM_SYNC_RETRY_S

        self._submit(v, GetParams(), done)

    # ------------------------------------------------------------------ missions
    def _mission_ack(
        self, v: Vehicle, peer: ms.Peer, result: int, mission_type: int, now: float
    ) -> None:
        link = self.links[peer.link]
        ack = mavlink.MAVLink_mission_ack_message(peer.system, peer.component, result, mission_type)
        self._send(link, v, ack, now)

    def _run_mission_actions(self, v: Vehicle, actions: list[ms.Action], now: float) -> None:
        for action in actions:
            peer = action.peer
            if isinstance(action, ms.Request):
                req = mavlink.MAVLink_mission_request_int_message(
                    peer.system, peer.component, action.seq, action.mission_type
                )
                self._send(self.links[peer.link], v, req, now)
            elif isinstance(action, ms.Ack):
                self._mission_ack(v, peer, action.result, action.mission_type, now)
            else:
                self._complete_upload(v, action, now)

    def _complete_upload(self, v: Vehicle, c: ms.Complete, now: float) -> None:
        link = self.links[c.peer.link]

        def finish(converted: ms.Converted) -> Callable[[CommandReply], None]:
            def done(reply: CommandReply) -> None:
                done_now = time.monotonic()
                if reply.accepted:
                    v.remember_upload(converted)
                    result = ms.Result.ACCEPTED
                else:
                    result = _MISSION_RESULT_OF_CODE.get(reply.code, ms.Result.ERROR)
                    self._statustext(link, v, f"{v.id}: mission refused: {reply.reason}", done_now)
                self._mission_ack(v, c.peer, result, c.mission_type, done_now)

            return done

        if not c.items:
            self._submit(v, MissionClear(), finish(ms.Converted([], [], [])))
            return
        try:
            cruise = v.params.value("MPC_XY_CRUISE")
            converted = ms.convert_upload(c.items, v.home_place(), cruise)
            command = MissionUpload(items=converted.items)
        except ms.MissionError as exc:
            self._statustext(link, v, f"{v.id}: {exc}", now)
            self._mission_ack(v, c.peer, exc.result, c.mission_type, now)
            return
        self._submit(v, command, finish(converted))

    def _on_mission_count(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        actions = v.uploader.on_count(peer, int(msg.count), int(msg.mission_type), now)
        self._run_mission_actions(v, actions, now)

    def _on_mission_item(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        item = self._wire_item(v, msg, peer, now)
        if item is not None:
            self._run_mission_actions(v, v.uploader.on_item(peer, item, now), now)

    def _wire_item(self, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> ms.WireItem | None:
        if msg.get_type() == "MISSION_ITEM_INT":
            x, y = int(msg.x), int(msg.y)
        else:  # MISSION_ITEM: degrees as floats (NaN: "here" for takeoff / land)
            lat, lon = float(msg.x), float(msg.y)
            here_ok = int(msg.command) in (ms.CMD_TAKEOFF, ms.CMD_LAND, ms.CMD_RTL)
            bad = None
            if not (math.isfinite(lat) and abs(lat) <= 90.0):
                bad = ms.Result.INVALID_PARAM5_X
            elif not (math.isfinite(lon) and abs(lon) <= 180.0):
                bad = ms.Result.INVALID_PARAM6_Y
            if bad is not None and not here_ok:
                v.uploader.on_cancel(peer)
                self._mission_ack(v, peer, bad, int(msg.mission_type), now)
                return None
            x, y = (0, 0) if bad is not None else (round(lat * 1e7), round(lon * 1e7))
        return ms.WireItem(
            seq=int(msg.seq),
            frame=int(msg.frame),
            command=int(msg.command),
            param1=float(msg.param1),
            param2=float(msg.param2),
            param3=float(msg.param3),
            param4=float(msg.param4),
            x=x,
            y=y,
            z=float(msg.z),
            autocontinue=int(msg.autocontinue),
            mission_type=int(msg.mission_type),
        )

    def _on_mission_ack(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        if int(msg.type) != ms.Result.ACCEPTED:
            v.uploader.on_cancel(peer)  # the GCS gave up on its upload

    def _on_mission_request_list(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        mission_type = int(msg.mission_type)
        if mission_type != ms.MISSION_TYPE_MISSION:
            self._mission_ack(v, peer, ms.Result.UNSUPPORTED, mission_type, now)
            return

        def done(reply: CommandReply) -> None:
            if reply.accepted and reply.mission is not None:
                v.download = v.wire_for_download(reply.mission)
            else:
                log.info(
                    "%s: MissionDownload not answered (%s); sending what MAVLink uploaded",
                    v.id,
                    reply.reason,
                )
                v.download = v.mission.wire if v.mission is not None else []
            count = mavlink.MAVLink_mission_count_message(
                peer.system, peer.component, len(v.download), mission_type
            )
            self._send(link, v, count, time.monotonic())

        self._submit(v, MissionDownload(), done)

    def _on_mission_request(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        mission_type = int(msg.mission_type)
        if mission_type != ms.MISSION_TYPE_MISSION:
            self._mission_ack(v, peer, ms.Result.UNSUPPORTED, mission_type, now)
            return
        seq = int(msg.seq)
        if not 0 <= seq < len(v.download):
            self._mission_ack(v, peer, ms.Result.INVALID_SEQUENCE, mission_type, now)
            return
        w = v.download[seq]
        current = 1 if seq == v.mission_current().seq else 0
        args = (
            w.seq,
            w.frame,
            w.command,
            current,
            w.autocontinue,
            w.param1,
            w.param2,
            w.param3,
            w.param4,
        )
        if msg.get_type() == "MISSION_REQUEST_INT":
            item = mavlink.MAVLink_mission_item_int_message(
                peer.system, peer.component, *args, w.x, w.y, w.z, mission_type
            )
        else:
            item = mavlink.MAVLink_mission_item_message(
                peer.system, peer.component, *args, w.x * 1e-7, w.y * 1e-7, w.z, mission_type
            )
        self._send(link, v, item, now)

    def _on_mission_clear_all(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        mission_type = int(msg.mission_type)
        if mission_type not in (ms.MISSION_TYPE_MISSION, ms.MISSION_TYPE_ALL):
            self._mission_ack(v, peer, ms.Result.UNSUPPORTED, mission_type, now)
            return

        def done(reply: CommandReply) -> None:
            if reply.accepted:
                v.remember_upload(ms.Converted([], [], []))
                result = ms.Result.ACCEPTED
            else:
                result = _MISSION_RESULT_OF_CODE.get(reply.code, ms.Result.ERROR)
            self._mission_ack(v, peer, result, mission_type, time.monotonic())

        self._submit(v, MissionClear(), done)

    def _on_mission_set_current(
        self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float
    ) -> None:
        """Jump to an item: restarts the mission there (our autopilot has no idle "current")."""
        index = ms.bus_index_of_seq(v.seqs(), int(msg.seq))

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if not reply.accepted:
                self._statustext(link, v, f"{v.id}: {reply.reason}", done_now)
            self._send_all(v, v.mission_current_msg(), done_now)

        self._submit(v, MissionStart(start_index=index), done)


def main(ctx: NodeContext) -> int:
    """Run the gateway for ``ctx.vehicle_ids`` (default: every vehicle of the scenario)."""
    try:
        options = parse_options(ctx.scenario.gateway, ctx.options)
    except OptionError as exc:
        log.error("%s", exc)
        return 2
    ids = list(ctx.vehicle_ids) or [v.id for v in ctx.scenario.vehicles]
    with NodeRuntime(ctx, role="gateway") as rt:
        try:
            gateway = Gateway(ctx.scenario, options, ids, rt.session, rt.keys)
        except OSError as exc:
            log.error("gateway: cannot open its UDP ports: %s", exc)
            return 2
        with gateway:
            rt.ready()
            gateway.run(rt.stop)
    return 0
