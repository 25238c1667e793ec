"""The pieces every part of the gateway is handed: the way out to ground stations
(:class:`Outbox`: telemetry, acknowledgements, rate-limited STATUSTEXTs) and the way to the
autopilots (:class:`Autopilots`: one command queue per vehicle, and who is alive).

The gateway (:mod:`gcs_bridge.gateway`) builds one of each and hands them to the handlers of
each MAVLink microservice (:mod:`gcs_bridge.handle_commands`, :mod:`gcs_bridge.handle_offboard`,
:mod:`gcs_bridge.handle_params`, :mod:`gcs_bridge.handle_missions`) and to the telemetry feed
(:mod:`gcs_bridge.feed`); they all run on the gateway's one loop thread.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable
from typing import Any

import zenoh

from gcs_bridge import mission as ms
from gcs_bridge.bus import Commander, Inbox
from gcs_bridge.commands import ACCEPTED, Facts
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.links import Link, LinkSet
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


def facts_of(v: Vehicle) -> Facts:
    """What command translation needs to know of a vehicle."""
    return Facts(
        origin=v.origin,
        home_amsl_m=v.home_amsl_m,
        home_enu=v.home_enu,
        position_enu=v.state.position_enu_m if v.state is not None else None,
        landed=v.status.landed if v.status is not None else True,
        takeoff_altitude_m=v.params.value("MIS_TAKEOFF_ALT"),
        mission_seqs=v.seqs(),
        cruise_m_s=v.params.cruise_m_s,
    )


class Outbox:
    """Messages to ground stations, as one vehicle: on one link or on all of its links."""

    def __init__(self, links: LinkSet) -> None:
        self._links = links
        self._text_budget: dict[tuple[str | None, int], tuple[float, float]] = {}
        self._text_id = 0  # the last STATUSTEXT.id given to a chunked text

    def send_all(self, v: Vehicle, msg: Msg, now: float) -> None:
        for link in self._links.of(v.sysid):
            link.send(v.sysid, msg, now)

    def send(self, link: Link, v: Vehicle, msg: Msg, now: float) -> None:
        link.send(v.sysid, msg, now)

    def link_of(self, peer: ms.Peer) -> Link:
        """The link ``peer`` spoke on."""
        return self._links.named(peer.link)

    def to_peer(self, peer: ms.Peer, v: Vehicle, msg: Msg, now: float) -> None:
        """On the link a transfer's peer spoke on."""
        self.link_of(peer).send(v.sysid, msg, now)

    def _text_allowed(self, link: Link | None, v: Vehicle, now: float) -> bool:
        """A token bucket per vehicle and link: a flood of refused frames must not become a
        flood of STATUSTEXTs to every ground station (the ACKs still answer each frame)."""
        key = (link.name if link is not None else None, v.sysid)
        tokens, last = self._text_budget.get(key, (float(STATUSTEXT_BURST), now))
        tokens = min(float(STATUSTEXT_BURST), tokens + (now - last) * STATUSTEXT_RATE_HZ)
        allowed = tokens >= 1.0
        self._text_budget[key] = (tokens - 1.0 if allowed else tokens, now)
        return allowed

    def statustext(self, link: Link | None, v: Vehicle, text: str, now: float) -> None:
        """A warning on ``link`` (None: on every link of the vehicle), rate-limited."""
        if not self._text_allowed(link, v, now):
            log.debug("%s: STATUSTEXT dropped (rate): %s", v.id, text)
            return
        text_id = 0
        if len(text) > STATUSTEXT_MAX:
            self._text_id = self._text_id % 65535 + 1
            text_id = self._text_id
        for msg in statustext_chunks(text, text_id):
            if link is None:
                self.send_all(v, msg, now)
            else:
                self.send(link, v, msg, now)

    def ack(
        self,
        link: Link,
        v: Vehicle,
        command: int,
        result: int,
        peer: ms.Peer,
        now: float,
        reason: str = "",
    ) -> None:
        """COMMAND_ACK to ``peer``; a refusal with a reason also says it in a STATUSTEXT."""
        ack = mavlink.MAVLink_command_ack_message(
            command, result, 0, 0, peer.system, peer.component
        )
        self.send(link, v, ack, now)
        if result != ACCEPTED and reason:
            self.statustext(link, v, f"{v.id}: {reason}", now)


class Autopilots:
    """The autopilots behind the vehicles: who is alive, and each one's command queue.

    Without a bus session (unit tests) nobody is alive by token and every command fails."""

    def __init__(
        self,
        session: zenoh.Session | None,
        keys: Keys,
        vehicles: list[Vehicle],
        cmd_timeout_s: float,
        inbox: Inbox,
    ) -> None:
        self._commanders: dict[str, Commander] = {}
        self.presence: Presence | None = None
        if session is not None:
            for v in vehicles:
                self._commanders[v.id] = Commander(
                    session, keys.vehicle_cmd(v.id), v.id, cmd_timeout_s, inbox
                )
            self.presence = Presence(session, keys)

    def close(self) -> None:
        if self.presence is not None:
            with contextlib.suppress(zenoh.ZError):
                self.presence.close()

    def names(self) -> frozenset[str]:
        """The live node names now (one copy, for :meth:`alive_in` over many vehicles)."""
        return self.presence.alive if self.presence is not None else frozenset()

    def alive(self, v: Vehicle, now: float) -> bool:
        """Is the vehicle's autopilot there (token, or a status lately)? Only then does it exist."""
        if now - v.last_status_wall_s < ALIVE_WITHOUT_TOKEN_S:
            return True
        return self.presence is not None and autopilot_node(v.id) in self.presence.alive

    @staticmethod
    def alive_in(v: Vehicle, now: float, names: frozenset[str]) -> bool:
        """:meth:`alive` against ``names`` (from :meth:`names`)."""
        return now - v.last_status_wall_s < ALIVE_WITHOUT_TOKEN_S or autopilot_node(v.id) in names

    def submit(self, v: Vehicle, command: Command, done: Done) -> None:
        """Queue ``command`` for the vehicle's autopilot; ``done`` runs on the loop."""
        commander = self._commanders.get(v.id)
        if commander is None:
            done(
                CommandReply(
                    vehicle_id=v.id, accepted=False, code=RejectCode.FAILED, reason="no bus"
                )
            )
            return
        commander.submit(command, done)

    def tell(self, v: Vehicle, command: Command) -> None:
        """A command whose reply nobody waits for (heartbeats, setpoints)."""
        self.submit(v, command, lambda reply: None)
