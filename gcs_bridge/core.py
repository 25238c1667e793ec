"""What every part of the gateway shares: its state, and how to send and to command.

The gateway (:mod:`gcs_bridge.gateway`) is one class assembled from this core and the handlers
of each MAVLink microservice (:mod:`gcs_bridge.handle_commands`, :mod:`gcs_bridge.handle_params`,
:mod:`gcs_bridge.handle_missions`); they all run on the gateway's one loop thread.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any

from gcs_bridge import mission as ms
from gcs_bridge.bus import Commander
from gcs_bridge.commands import ACCEPTED, Facts
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.links import Link
from gcs_bridge.options import GatewayOptions
from gcs_bridge.telemetry import StreamSchedule
from gcs_bridge.vehicle import Vehicle
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import Command, CommandReply, RejectCode
from swarmbus.session import Presence

log = logging.getLogger(__name__)

ALIVE_WITHOUT_TOKEN_S = 3.0
STATUSTEXT_MAX = 50
STATUSTEXT_CHUNKS_MAX = 4  # a longer text is cut after 4 MAVLink 2 chunks (200 characters)
STATUSTEXT_BURST = 10  # refusal texts per vehicle and link, then STATUSTEXT_RATE_HZ
STATUSTEXT_RATE_HZ = 5.0

Handler = Callable[[Link, Vehicle, Msg, ms.Peer, float], None]
Done = Callable[[CommandReply], None]


def text_of(value: Any) -> str:
    """A MAVLink char[] field as text (pymavlink gives bytes or str)."""
    if isinstance(value, bytes | bytearray):
        return bytes(value).split(b"\0", 1)[0].decode("ascii", "replace")
    return str(value).split("\0", 1)[0]


def statustext_chunks(text: str, text_id: int) -> list[Msg]:
    """STATUSTEXT messages for ``text``: one when it fits, else MAVLink 2 chunks sharing
    ``text_id`` (QGroundControl and MAVSDK join them; the last chunk is shorter than 50
    characters, so a text of a multiple of 50 ends with an empty chunk)."""
    raw = text.encode("ascii", "replace")[: STATUSTEXT_MAX * STATUSTEXT_CHUNKS_MAX - 1]
    if len(raw) <= STATUSTEXT_MAX:
        return [mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, raw)]
    pieces = [raw[i : i + STATUSTEXT_MAX] for i in range(0, len(raw), STATUSTEXT_MAX)]
    if len(pieces[-1]) == STATUSTEXT_MAX:
        pieces.append(b"")
    return [
        mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, piece, text_id, seq)
        for seq, piece in enumerate(pieces)
    ]


class Core:
    """State shared by the handlers; :class:`gcs_bridge.gateway.Gateway` fills it in."""

    options: GatewayOptions
    keys: Keys
    vehicles: dict[str, Vehicle]
    by_sysid: dict[int, Vehicle]
    links: dict[str, Link]
    links_of: dict[int, list[Link]]
    schedules: dict[tuple[str, int], StreamSchedule]
    _commanders: dict[str, Commander]
    _presence: Presence | None
    _inflight: set[tuple[int, int, int, int]]
    _param_sync: dict[str, float]
    _text_budget: dict[tuple[str | None, int], tuple[float, float]]  # → (tokens, last wall s)
    _text_id: int  # the last STATUSTEXT.id given to a chunked text

    # ------------------------------------------------------------------ presence
    def alive(self, v: Vehicle, now: float) -> bool:
        """Is the vehicle's autopilot there (token, or a status lately)? Only then does it exist."""
        if now - v.last_status_wall_s < ALIVE_WITHOUT_TOKEN_S:
            return True
        return self._presence is not None and autopilot_node(v.id) in self._presence.alive

    def alive_in(self, v: Vehicle, now: float, names: frozenset[str]) -> bool:
        """:meth:`alive` against ``names``, one copy of the alive names for many vehicles."""
        return now - v.last_status_wall_s < ALIVE_WITHOUT_TOKEN_S or autopilot_node(v.id) in names

    # ------------------------------------------------------------------ sending
    def _send_all(self, v: Vehicle, msg: Msg, now: float) -> None:
        for link in self.links_of[v.sysid]:
            link.send(v.sysid, msg, now)

    def _send(self, link: Link, v: Vehicle, msg: Msg, now: float) -> None:
        link.send(v.sysid, msg, now)

    def _text_allowed(self, link: Link | None, v: Vehicle, now: float) -> bool:
        """A token bucket per vehicle and link: a flood of refused frames must not become a
        flood of STATUSTEXTs to every ground station (the ACKs still answer each frame)."""
        key = (link.name if link is not None else None, v.sysid)
        tokens, last = self._text_budget.get(key, (float(STATUSTEXT_BURST), now))
        tokens = min(float(STATUSTEXT_BURST), tokens + (now - last) * STATUSTEXT_RATE_HZ)
        allowed = tokens >= 1.0
        self._text_budget[key] = (tokens - 1.0 if allowed else tokens, now)
        return allowed

    def _statustext(self, link: Link | None, v: Vehicle, text: str, now: float) -> None:
        if not self._text_allowed(link, v, now):
            log.debug("%s: STATUSTEXT dropped (rate): %s", v.id, text)
            return
        text_id = 0
        if len(text) > STATUSTEXT_MAX:
            self._text_id = self._text_id % 65535 + 1
            text_id = self._text_id
        for msg in statustext_chunks(text, text_id):
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
