"""The mission microservice: upload, download, clear and set-current, per vehicle."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable

from gcs_bridge import mission as ms
from gcs_bridge import plans
from gcs_bridge.core import Autopilots, Handler, Outbox
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.links import Link
from gcs_bridge.vehicle import Vehicle
from swarmbus.messages import (
    Command,
    CommandReply,
    GeofenceUpload,
    MissionClear,
    MissionDownload,
    MissionStart,
    MissionUpload,
    RallyUpload,
    RejectCode,
)

log = logging.getLogger(__name__)

_MISSION_RESULT_OF_CODE = {
    RejectCode.DENIED: ms.Result.DENIED,
    RejectCode.INVALID: ms.Result.INVALID,
    RejectCode.UNSUPPORTED: ms.Result.UNSUPPORTED,
}


class MissionHandlers:
    """Each vehicle's mission, geofence and rally transfers: its
    :class:`~gcs_bridge.mission.Uploader` drives uploads; downloads answer from what the
    autopilot or the last upload says."""

    def __init__(self, out: Outbox, autopilots: Autopilots) -> None:
        self._out = out
        self._autopilots = autopilots

    def handlers(self) -> dict[str, Handler]:
        return {
            "MISSION_COUNT": self.on_count,
            "MISSION_ITEM_INT": self.on_item,
            "MISSION_ITEM": self.on_item,
            "MISSION_ACK": self.on_ack,
            "MISSION_REQUEST_LIST": self.on_request_list,
            "MISSION_REQUEST_INT": self.on_request,
            "MISSION_REQUEST": self.on_request,
            "MISSION_CLEAR_ALL": self.on_clear_all,
            "MISSION_SET_CURRENT": self.on_set_current,
        }

    def on_timer(self, v: Vehicle, now: float) -> None:
        """An upload's item re-requests and its end when the ground station went quiet."""
        if v.uploader.active:
            self._run_actions(v, v.uploader.on_timer(now), now)

    def _mission_ack(
        self, v: Vehicle, peer: ms.Peer, result: int, mission_type: int, now: float
    ) -> None:
        ack = mavlink.MAVLink_mission_ack_message(peer.system, peer.component, result, mission_type)
        self._out.to_peer(peer, v, ack, now)

    def _run_actions(self, v: Vehicle, actions: list[ms.Action], now: float) -> None:
        for action in actions:
            peer = action.peer
            if isinstance(action, ms.Request):
                req = mavlink.MAVLink_mission_request_int_message(
                    peer.system, peer.component, action.seq, action.mission_type
                )
                self._out.to_peer(peer, v, req, now)
            elif isinstance(action, ms.Ack):
                self._mission_ack(v, peer, action.result, action.mission_type, now)
            else:
                self._complete_upload(v, action, now)

    def _complete_upload(self, v: Vehicle, c: ms.Complete, now: float) -> None:
        link = self._out.link_of(c.peer)

        def finish(converted: ms.Converted) -> Callable[[CommandReply], None]:
            def done(reply: CommandReply) -> None:
                done_now = time.monotonic()
                if reply.accepted:
                    v.remember_upload(converted)
                    result = ms.Result.ACCEPTED
                else:
                    result = _MISSION_RESULT_OF_CODE.get(reply.code, ms.Result.ERROR)
                    self._out.statustext(
                        link, v, f"{v.id}: mission refused: {reply.reason}", done_now
                    )
                self._mission_ack(v, c.peer, result, c.mission_type, done_now)

            return done

        if c.mission_type != ms.MISSION_TYPE_MISSION:
            self._complete_plan_upload(v, c, now)
            return
        if not c.items:
            self._autopilots.submit(v, MissionClear(), finish(ms.Converted([], [], [])))
            return
        try:
            cruise = v.params.cruise_m_s
            converted = ms.convert_upload(c.items, v.home_place(), cruise)
            command = MissionUpload(items=converted.items)
        except ms.MissionError as exc:
            self._out.statustext(link, v, f"{v.id}: {exc}", now)
            self._mission_ack(v, c.peer, exc.result, c.mission_type, now)
            return
        self._autopilots.submit(v, command, finish(converted))

    def _complete_plan_upload(self, v: Vehicle, c: ms.Complete, now: float) -> None:
        """A geofence or rally upload: to the autopilot, then ACK; kept for download."""
        link = self._out.link_of(c.peer)
        try:
            command: Command
            if c.mission_type == ms.MISSION_TYPE_FENCE:
                command = GeofenceUpload(zones=plans.convert_fence(c.items, v.home_place()))
            else:
                command = RallyUpload(points_enu_m=plans.convert_rally(c.items, v.home_place()))
        except ms.MissionError as exc:
            self._out.statustext(link, v, f"{v.id}: {exc}", now)
            self._mission_ack(v, c.peer, exc.result, c.mission_type, now)
            return

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if reply.accepted:
                v.plans[c.mission_type] = list(c.items)
                result = ms.Result.ACCEPTED
            else:
                result = _MISSION_RESULT_OF_CODE.get(reply.code, ms.Result.ERROR)
                self._out.statustext(link, v, f"{v.id}: refused: {reply.reason}", done_now)
            self._mission_ack(v, c.peer, result, c.mission_type, done_now)

        self._autopilots.submit(v, command, done)

    def on_count(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        actions = v.uploader.on_count(peer, int(msg.count), int(msg.mission_type), now)
        self._run_actions(v, actions, now)

    def on_item(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        item = self._wire_item(v, msg, peer, now)
        if item is not None:
            self._run_actions(v, v.uploader.on_item(peer, item, now), now)

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

    def _plan_type(self, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> int | None:
        """The message's mission type if it is mission, fence or rally; else UNSUPPORTED."""
        mission_type = int(msg.mission_type)
        if mission_type not in ms.PLAN_TYPES:
            self._mission_ack(v, peer, ms.Result.UNSUPPORTED, mission_type, now)
            return None
        return mission_type

    def on_ack(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        if int(msg.type) != ms.Result.ACCEPTED:
            v.uploader.on_cancel(peer)  # the GCS gave up on its upload

    def on_request_list(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        mission_type = self._plan_type(v, msg, peer, now)
        if mission_type is None:
            return
        if mission_type != ms.MISSION_TYPE_MISSION:
            count = len(v.plans.get(mission_type, []))
            msg_count = mavlink.MAVLink_mission_count_message(
                peer.system, peer.component, count, mission_type
            )
            self._out.send(link, v, msg_count, now)
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
            self._out.send(link, v, count, time.monotonic())

        self._autopilots.submit(v, MissionDownload(), done)

    def on_request(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        mission_type = self._plan_type(v, msg, peer, now)
        if mission_type is None:
            return
        seq = int(msg.seq)
        served = (
            v.download if mission_type == ms.MISSION_TYPE_MISSION else v.plans.get(mission_type, [])
        )
        if not 0 <= seq < len(served):
            self._mission_ack(v, peer, ms.Result.INVALID_SEQUENCE, mission_type, now)
            return
        w = served[seq]
        is_mission = mission_type == ms.MISSION_TYPE_MISSION
        current = 1 if is_mission and seq == v.mission_current().seq else 0
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
        self._out.send(link, v, item, now)

    def on_clear_all(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        mission_type = int(msg.mission_type)
        if mission_type not in (*ms.PLAN_TYPES, ms.MISSION_TYPE_ALL):
            self._mission_ack(v, peer, ms.Result.UNSUPPORTED, mission_type, now)
            return
        everything = mission_type == ms.MISSION_TYPE_ALL
        clears: list[tuple[int, Command]] = [
            (t, c)
            for t, c in (
                (ms.MISSION_TYPE_MISSION, MissionClear()),
                (ms.MISSION_TYPE_FENCE, GeofenceUpload(zones=[])),
                (ms.MISSION_TYPE_RALLY, RallyUpload(points_enu_m=[])),
            )
            if everything or t == mission_type
        ]
        refusals: list[CommandReply] = []

        def cleared(kind: int) -> Callable[[CommandReply], None]:
            def done(reply: CommandReply) -> None:
                if not reply.accepted:
                    refusals.append(reply)
                elif kind == ms.MISSION_TYPE_MISSION:
                    v.remember_upload(ms.Converted([], [], []))
                else:
                    v.plans.pop(kind, None)
                if kind != clears[-1][0]:
                    return
                result = ms.Result.ACCEPTED
                if refusals:
                    result = _MISSION_RESULT_OF_CODE.get(refusals[0].code, ms.Result.ERROR)
                self._mission_ack(v, peer, result, mission_type, time.monotonic())

            return done

        for kind, command in clears:
            self._autopilots.submit(v, command, cleared(kind))

    def on_set_current(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        """Jump to an item: restarts the mission there (our autopilot has no idle "current").
        An item that does not exist is refused here (STATUSTEXT, MISSION_CURRENT unchanged)."""
        seq = int(msg.seq)
        if seq >= v.mission_total():
            self._out.statustext(link, v, f"{v.id}: mission item {seq} does not exist", now)
            self._out.send_all(v, v.mission_current_msg(), now)
            return
        index = ms.bus_index_of_seq(v.seqs(), seq)

        def done(reply: CommandReply) -> None:
            done_now = time.monotonic()
            if not reply.accepted:
                self._out.statustext(link, v, f"{v.id}: {reply.reason}", done_now)
            self._out.send_all(v, v.mission_current_msg(), done_now)

        self._autopilots.submit(v, MissionStart(start_index=index), done)
