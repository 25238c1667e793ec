"""The parameter microservice: PARAM_REQUEST_LIST / _READ / PARAM_SET against the autopilot."""

from __future__ import annotations

import logging
import time

from gcs_bridge import mission as ms
from gcs_bridge.core import Autopilots, Handler, Outbox, text_of
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.links import Link
from gcs_bridge.params import ParamError
from gcs_bridge.vehicle import Vehicle
from swarmbus.messages import CommandReply, GetParams, RejectCode, SetParam

log = logging.getLogger(__name__)

PARAM_SYNC_RETRY_S = 5.0


class ParamHandlers:
    """PARAM_* against each vehicle's :class:`~gcs_bridge.params.ParamTable`, and the one
    ``GetParams`` that fills the table from the autopilot once it is there."""

    def __init__(self, out: Outbox, autopilots: Autopilots) -> None:
        self._out = out
        self._autopilots = autopilots
        self._sync: dict[str, float] = {}  # vehicle id → next attempt (wall s); -1 busy

    def handlers(self) -> dict[str, Handler]:
        return {
            "PARAM_REQUEST_LIST": self.on_request_list,
            "PARAM_REQUEST_READ": self.on_request_read,
            "PARAM_SET": self.on_set,
        }

    def _param_value(self, link: Link, v: Vehicle, name: str, now: float) -> None:
        index = v.params.index_of(name)
        spec = v.params.spec(name)
        if index is None or spec is None:
            return
        msg = mavlink.MAVLink_param_value_message(
            name.encode("ascii"), v.params.wire_value(name), spec.param_type, v.params.count, index
        )
        self._out.send(link, v, msg, now)

    def on_request_list(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        for spec in v.params.specs:
            self._param_value(link, v, spec.name, now)

    def on_request_read(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        index = int(msg.param_index)
        if index >= 0:
            if index < v.params.count:
                self._param_value(link, v, v.params.specs[index].name, now)
            return
        self._param_value(link, v, text_of(msg.param_id), now)

    def on_set(self, link: Link, v: Vehicle, msg: Msg, peer: ms.Peer, now: float) -> None:
        name = text_of(msg.param_id)
        spec = v.params.spec(name)
        if spec is None:
            log.debug("%s: PARAM_SET of unknown parameter %r ignored", v.id, name)
            return
        try:
            value = v.params.decode_set(name, float(msg.param_value))
        except ParamError as exc:
            self._out.statustext(link, v, f"{v.id}: {exc}", now)
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
                self._out.statustext(link, v, f"{v.id}: {name} refused: {reply.reason}", done_now)
            self._param_value(link, v, name, done_now)

        self._autopilots.submit(v, SetParam(name=name, value=value), done)

    def sync(self, v: Vehicle, now: float) -> None:
        """Once the autopilot is there, take its parameter values (GetParams)."""
        if v.params_synced or v.status is None:
            return
        next_try = self._sync.get(v.id, 0.0)
        if next_try < 0 or now < next_try:
            return
        self._sync[v.id] = -1.0

        def done(reply: CommandReply) -> None:
            if reply.accepted and reply.params is not None:
                v.params.merge_from_autopilot(reply.params)
                v.params_synced = True
            elif reply.code == RejectCode.UNSUPPORTED:
                log.info("%s: autopilot has no parameters; the gateway keeps its own", v.id)
                v.params_synced = True
            else:
                self._sync[v.id] = time.monotonic() + PARAM_SYNC_RETRY_S

        self._autopilots.submit(v, GetParams(), done)
