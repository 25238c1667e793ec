"""COMMAND_LONG / COMMAND_INT and SET_MODE (:class:`CommandHandlers`), and ground-station
heartbeats (:class:`GcsHeartbeats`: the autopilots' data-link-loss failsafe)."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from gcs_bridge import mission as ms
from gcs_bridge.commands import (
    ACCEPTED,
    DENIED,
    TEMPORARILY_REJECTED,
    UNSUPPORTED,
    CommandRequest,
    Translation,
    refuse,
    result_of_reply,
    translate,
    translate_mode,
)
from gcs_bridge.core import Autopilots, Done, Handler, Outbox, facts_of
from gcs_bridge.dialect import (
    MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES,
    MAV_CMD_REQUEST_PROTOCOL_VERSION,
    MAVLINK_MSG_ID_PROTOCOL_VERSION,
    Msg,
    mavlink,
    protocol_version_message,
)
from gcs_bridge.links import Link, LinkSet
from gcs_bridge.modes import decode_custom_mode
from gcs_bridge.telemetry import BUILDERS, ID_MISSION_CURRENT
from gcs_bridge.vehicle import ArmIntent, Vehicle
from swarmbus.messages import (
    Arm,
    Command,
    CommandReply,
    Disarm,
    FlightMode,
    GcsHeartbeat,
    Hold,
    SetMode,
    Takeoff,
)

log = logging.getLogger(__name__)

GCS_HEARTBEAT_FORWARD_S = 0.5
MAX_MESSAGE_ID = 65535  # MESSAGE_INTERVAL.message_id is a uint16
GCS_LINK_TIMEOUT_S = 3.0  # wall: a GCS silent this long is gone (QGC's own is ~3.5 s)


LocalCommand = Callable[[Link, Vehicle, CommandRequest, ms.Peer, float], None]


class GcsHeartbeats:
    """A ground station is there: each vehicle of its link is told (``GcsHeartbeat``), and
    while it is, the telling repeats once per sim second (:meth:`keep_alive`)."""

    def __init__(
        self, links: LinkSet, by_sysid: dict[int, Vehicle], autopilots: Autopilots
    ) -> None:
        self._links = links
        self._by_sysid = by_sysid
        self._autopilots = autopilots

    def on_heartbeat(self, link: Link, now: float) -> None:
        link.gcs_heard_s = now
        for sysid in link.sysids:
            v = self._by_sysid[sysid]
            if now - v.last_gcs_heartbeat_s >= GCS_HEARTBEAT_FORWARD_S:
                self._forward(v, now)

    def heard(self, link: Link, now: float) -> bool:
        """Was a ground station heard on ``link`` lately (wall)?"""
        return now - link.gcs_heard_s <= GCS_LINK_TIMEOUT_S

    def _forward(self, v: Vehicle, now: float) -> None:
        if not self._autopilots.alive(v, now):
            return
        v.last_gcs_heartbeat_s = now
        if v.state is not None:
            v.last_gcs_heartbeat_sim_s = v.state.sim_time_s
        self._autopilots.tell(v, GcsHeartbeat(source="mavlink"))

    def keep_alive(self, v: Vehicle, now: float) -> None:
        """The GCS beats once per wall second, the autopilot's link timeout is in sim seconds,
        and the simulation may run many times faster than real time. So while a GCS was heard
        within GCS_LINK_TIMEOUT_S (wall), its heartbeat is repeated once per sim second; when it
        falls silent the repeats stop and the autopilot's own timeout runs in sim time."""
        if v.state is None or v.state.sim_time_s - v.last_gcs_heartbeat_sim_s < 1.0:
            return
        if any(self.heard(link, now) for link in self._links.of(v.sysid)):
            self._forward(v, now)


class CommandHandlers:
    """COMMAND_LONG / COMMAND_INT and SET_MODE: answered here (message streams, identity) or
    translated and sent to the autopilot, whose reply becomes the COMMAND_ACK."""

    def __init__(
        self,
        links: LinkSet,
        out: Outbox,
        autopilots: Autopilots,
        refuse_broadcast_disarm: bool = False,
    ) -> None:
        self._refuse_broadcast_disarm = refuse_broadcast_disarm
        self._links = links
        self._out = out
        self._autopilots = autopilots
        self._inflight: set[tuple[int, int, int, int]] = set()
        self._local: dict[int, LocalCommand] = {
            int(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL): self._cmd_set_message_interval,
            int(mavlink.MAV_CMD_GET_MESSAGE_INTERVAL): self._cmd_get_message_interval,
            int(mavlink.MAV_CMD_REQUEST_MESSAGE): self._cmd_request_message,
            MAV_CMD_REQUEST_PROTOCOL_VERSION: self._cmd_request_protocol_version,
            MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: self._cmd_request_autopilot_version,
        }

    def handlers(self) -> dict[str, Handler]:
        return {
            "COMMAND_LONG": self.on_command,
            "COMMAND_INT": self.on_command,
            "SET_MODE": self.on_set_mode,
        }

    def _select_while_disarmed(
        self, v: Vehicle, command: Command, now: float
    ) -> Translation | None:
        """PX4 lets a GCS pick takeoff or mission mode while disarmed and fly it on arming
        (QGC's takeoff and start-mission flows). Our autopilot takes those only once armed,
        so the gateway keeps the selection and sends it right after a successful arm. Once an
        Arm is on its way the vehicle counts as armed: the command follows it to the autopilot."""
        if v.status is None or v.armed or v.arming(now):
            return None
        if isinstance(command, Takeoff) or (
            isinstance(command, SetMode) and command.mode == FlightMode.MISSION
        ):
            return self._select_to_arm_in(v, command)
        if isinstance(command, Hold):
            v.intent = None
            return Translation()
        return None

    @staticmethod
    def _select_to_arm_in(v: Vehicle, command: Command) -> Translation:
        why = v.armable()
        if why is not None:
            return refuse(TEMPORARILY_REJECTED, f"cannot select a mode to arm in: {why}")
        if isinstance(command, Takeoff):
            v.intent = ArmIntent(FlightMode.TAKEOFF, command.altitude_m)
        elif v.status is not None and v.status.mission_count == 0:
            return refuse(TEMPORARILY_REJECTED, "no mission uploaded")
        else:
            v.intent = ArmIntent(FlightMode.MISSION)
        return Translation()

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
                    self._out.statustext(
                        None, v, f"{v.id}: {intent.mode} refused: {r.reason}", time.monotonic()
                    )
                    self._out.send_all(v, v.heartbeat(), time.monotonic())

            self._autopilots.submit(v, follow, flown)

        return armed

    def on_command(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        if msg.get_type() == "COMMAND_LONG":
            req = CommandRequest.from_long(msg)
        else:
            req = CommandRequest.from_int(msg)
        key = (v.sysid, peer.system, peer.component, req.command)
        if key in self._inflight:
            return  # a client's retry of a command still waiting for the autopilot
        local = self._local.get(req.command)
        if local is not None:
            local(link, v, req, peer, now)
            return
        t = self._translate(v, req, now)
        if t is not None and self._broadcast_force_disarm(link, v, msg, t, peer):
            t = refuse(DENIED, "a force disarm to every system is refused here")
        if t is None:
            self._out.ack(link, v, req.command, UNSUPPORTED, peer, now)
        elif t.bus is None:
            self._out.ack(link, v, req.command, t.result, peer, now, t.reason)
        else:
            self._to_autopilot(link, v, req, t.bus, peer, key, now)

    def _broadcast_force_disarm(
        self, link: Link, v: Vehicle, msg: Msg, t: Translation, peer: ms.Peer
    ) -> bool:
        """Log a force disarm sent to every system (target_system 0: one datagram would drop
        the whole swarm); True when the option refuses it."""
        if not (isinstance(t.bus, Disarm) and t.bus.force and msg.target_system == 0):
            return False
        log.warning(
            "%s: force disarm to every system (target_system 0) from %s:%d, system %d, "
            "for %s: %s", link.name, *peer.addr, peer.system, v.id,
            "refused (refuse_broadcast_disarm)" if self._refuse_broadcast_disarm else "sent on",
        )  # fmt: skip
        return self._refuse_broadcast_disarm

    def _translate(self, v: Vehicle, req: CommandRequest, now: float) -> Translation | None:
        """The command for the bus, or the gateway's own answer (a selection kept for arming
        counts as done, and the heartbeat shows it at once); None: not supported."""
        t = translate(req, facts_of(v))
        if t is None or t.bus is None:
            return t
        t = self._select_while_disarmed(v, t.bus, now) or t
        if t.bus is None and t.result == ACCEPTED:
            self._out.send_all(v, v.heartbeat(), now)
        return t

    def _to_autopilot(
        self,
        link: Link,
        v: Vehicle,
        req: CommandRequest,
        command: Command,
        peer: ms.Peer,
        key: tuple[int, int, int, int],
        now: float,
    ) -> None:
        """Send ``command``; the autopilot's reply becomes the ACK (retries wait for it)."""
        self._inflight.add(key)

        def done(reply: CommandReply) -> None:
            self._inflight.discard(key)
            done_now = time.monotonic()
            self._out.ack(
                link, v, req.command, result_of_reply(reply), peer, done_now, reply.reason
            )

        completion: Done = done
        if isinstance(command, Disarm):
            v.intent = None
            v.arming_since_s = None
        elif isinstance(command, Arm):
            completion = self._arming(v, now, done)
            if v.intent is not None:
                intent, v.intent = v.intent, None
                completion = self._arm_then_intent(v, intent, completion)
        self._autopilots.submit(v, command, completion)

    def _arming(self, v: Vehicle, now: float, done: Done) -> Done:
        """Completion of an Arm: until a status says armed, the vehicle counts as arming."""
        v.arming_since_s = now

        def replied(reply: CommandReply) -> None:
            if not reply.accepted:
                v.arming_since_s = None
            done(reply)

        return replied

    def _cmd_set_message_interval(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        schedule = self._links.schedule(link, v.sysid)
        ok = math.isfinite(req.param1) and schedule.set_interval_us(int(req.param1), req.param2)
        self._out.ack(link, v, req.command, ACCEPTED if ok else DENIED, peer, now)

    def _cmd_get_message_interval(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        if not (math.isfinite(req.param1) and 0 <= req.param1 <= MAX_MESSAGE_ID):
            self._out.ack(link, v, req.command, DENIED, peer, now)  # MESSAGE_INTERVAL has a uint16
            return
        msg_id = int(req.param1)
        interval = self._links.schedule(link, v.sysid).interval_us(msg_id)
        self._out.ack(link, v, req.command, ACCEPTED, peer, now)
        self._out.send(link, v, mavlink.MAVLink_message_interval_message(msg_id, interval), now)

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
            self._out.ack(link, v, req.command, UNSUPPORTED, peer, now)
            return
        msg = self._requested_message(v, msg_id)
        if msg is None:  # e.g. HOME_POSITION before the autopilot reported one
            self._out.ack(link, v, req.command, TEMPORARILY_REJECTED, peer, now)
            return
        self._out.ack(link, v, req.command, ACCEPTED, peer, now)
        self._out.send(link, v, msg, now)

    def _cmd_request_protocol_version(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        self._out.ack(link, v, req.command, ACCEPTED, peer, now)
        self._out.send(link, v, protocol_version_message(), now)

    def _cmd_request_autopilot_version(
        self, link: Link, v: Vehicle, req: CommandRequest, peer: ms.Peer, now: float
    ) -> None:
        self._out.ack(link, v, req.command, ACCEPTED, peer, now)
        self._out.send(link, v, v.autopilot_version(), now)

    def on_set_mode(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        """SET_MODE has no ACK: the client watches the heartbeat's custom_mode change."""
        mode = decode_custom_mode(int(msg.custom_mode))
        t = translate_mode(float(msg.base_mode), mode.main, mode.sub, facts_of(v))
        if t.bus is not None:
            t = self._select_while_disarmed(v, t.bus, now) or t
        if t.bus is None:
            if t.result == ACCEPTED:
                self._out.send_all(v, v.heartbeat(), now)
            else:
                self._out.statustext(link, v, f"{v.id}: {t.reason}", now)
            return

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if not reply.accepted:
                self._out.statustext(
                    link, v, f"{v.id}: mode change refused: {reply.reason}", done_now
                )
            self._out.send_all(v, v.heartbeat(), done_now)

        self._autopilots.submit(v, t.bus, done)
