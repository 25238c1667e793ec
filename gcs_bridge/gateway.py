"""``plumeswarm node gateway``: the MAVLink 2 gateway between ground stations and the bus
(:class:`Gateway`: the one loop and its wiring); options in
:class:`~gcs_bridge.options.GatewayOptions`. See docs/qgroundcontrol.md ("Inside the gateway").
"""

from __future__ import annotations

import contextlib
import logging
import select
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from gcs_bridge import mission as ms
from gcs_bridge.bus import (
    KIND_READING,
    KIND_STATUS,
    STREAM_IDLE_POLL_S,
    STREAM_POLL_S,
    Inbox,
    Streams,
    Waker,
    subscribe_statuses,
)
from gcs_bridge.core import Autopilots, Handler, Outbox
from gcs_bridge.dialect import Msg
from gcs_bridge.feed import TelemetryFeed
from gcs_bridge.handle_commands import CommandHandlers, GcsHeartbeats
from gcs_bridge.handle_missions import MissionHandlers
from gcs_bridge.handle_offboard import OffboardHandlers
from gcs_bridge.handle_params import ParamHandlers
from gcs_bridge.links import Link, LinkSet, Signing
from gcs_bridge.options import (
    GatewayOptions,
    exposure_note,
    peer_host,
    signing_key,
    unsigned_exposed,
)
from gcs_bridge.vehicle import Vehicle
from plume_atmosphere.wind import wind_from_scenario, wind_vector_enu
from swarmbus.closeable import Closeable
from swarmbus.codec import decode_or_none
from swarmbus.keys import Keys
from swarmbus.messages import VehicleStatus
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, role_options
from swarmbus.scenario import GatewaySpec, Scenario, not_on_mavlink_note
from swarmbus.vehicle_types import load_vehicle_type
from swarmbus.views import TickView

log = logging.getLogger(__name__)

TICK_S = 0.1  # wall-clock housekeeping: heartbeats, transfer timeouts, parameter sync
HEARTBEAT_PERIOD_S = 1.0  # MAVLink's 1 Hz heartbeat


def open_links(section: GatewaySpec, o: GatewayOptions, vehicles: list[Vehicle]) -> LinkSet:
    """The shared GCS link (every vehicle) and, unless turned off, each vehicle's API link;
    :class:`OptionError` for a bad option or key file."""
    key = signing_key(section)
    exposed = unsigned_exposed(section, o)
    if exposed:
        log.warning("%s", exposure_note(exposed))
    signing = open_signing(key, o.signing_state) if key is not None else None
    links = LinkSet(o.rates_hz(), [v.sysid for v in vehicles], signing)
    try:
        links.add(
            Link(
                "gcs",
                (o.bind_host_for(section, "gcs"), o.gcs_bind_port),
                (peer_host(section, "gcs"), section.gcs_port),
                [v.sysid for v in vehicles],
                signing if o.signs("gcs") else None,
                link_id=0,
            )
        )
        if not o.api_links:
            return links
        for v in vehicles:
            bind_port = o.api_bind_port_base + v.index if o.api_bind_port_base else 0
            link = Link(
                f"api-{v.id}",
                (o.bind_host_for(section, "api"), bind_port),
                (peer_host(section, "api"), section.api_port_base + v.index),
                [v.sysid],
                signing if o.signs("api") else None,
                link_id=(v.index + 1) % 256,
            )
            links.add(link)
    except OSError:
        links.close()
        raise
    return links


def open_signing(key: bytes, state: str) -> Signing:
    """The links' shared signing state, kept in the file ``state`` (empty: in memory)."""
    path = Path(state).expanduser() if state else None
    try:
        return Signing(key, path)
    except OSError as exc:
        raise OptionError(
            f"--set signing_state={state}: cannot open it ({exc.strerror or exc})"
        ) from None


class Gateway(Closeable):
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
        wind = wind_vector_enu(scenario.wind.speed_m_s, scenario.wind.from_deg)
        index_of = {v.id: i for i, v in enumerate(scenario.vehicles)}
        off_mavlink = set(scenario.not_on_mavlink(vehicle_ids))
        if off_mavlink:
            log.warning("%s", not_on_mavlink_note(len(off_mavlink)))
        on_mavlink = [vid for vid in vehicle_ids if vid not in off_mavlink]
        # a fixed wing's airspeed is against the physics' own wind (gusts and all)
        planes = any(load_vehicle_type(scenario.vehicle(vid).type).fixed_wing for vid in on_mavlink)
        air = wind_from_scenario(scenario) if planes else None
        self.vehicles = {
            vid: Vehicle(scenario, vid, index_of[vid], wind, air) for vid in on_mavlink
        }
        self.by_sysid = {v.sysid: v for v in self.vehicles.values()}
        vehicles = list(self.vehicles.values())
        self.links = open_links(scenario.gateway, options, vehicles)
        self.waker = Waker()
        self.inbox = Inbox(self.waker)
        self.out = Outbox(self.links)
        self.autopilots = Autopilots(session, keys, vehicles, options.cmd_timeout_s, self.inbox)
        self._presence = self.autopilots.presence
        self._subs: list[Any] = []
        self._streams: Streams | None = None
        if session is not None:
            self._subs = [subscribe_statuses(session, keys, set(self.vehicles), self.inbox)]
            self._streams = Streams(session, keys, set(self.vehicles))
        self._stream_poll_s = STREAM_IDLE_POLL_S
        self._dormant = False  # nobody listens on any link (see _take_streams)
        self.gcs = GcsHeartbeats(self.links, self.by_sysid, self.autopilots)
        self.feed = TelemetryFeed(
            vehicles, self.links, self.out, self.autopilots, self.gcs, self._streams
        )
        self.commands = CommandHandlers(
            self.links, self.out, self.autopilots, options.refuse_broadcast_disarm
        )
        self.params = ParamHandlers(self.out, self.autopilots)
        self.missions = MissionHandlers(self.out, self.autopilots)
        self._handlers: dict[str, Handler] = {
            **self.commands.handlers(),
            **self.params.handlers(),
            **self.missions.handlers(),
            **OffboardHandlers(self.autopilots).handlers(),
        }
        self._next_heartbeat_s = 0.0
        self._next_tick_s = 0.0

    def close(self) -> None:
        for sub in self._subs:
            with contextlib.suppress(zenoh.ZError):
                sub.undeclare()
        if self._streams is not None:
            with contextlib.suppress(zenoh.ZError):
                self._streams.undeclare()
        self.autopilots.close()
        self.links.close()
        self.waker.close()

    # ------------------------------------------------------------------ the loop
    def run(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self.poll(0.2)

    def poll(self, max_wait_s: float) -> None:
        """Wait for traffic (at most ``max_wait_s``), handle all of it, do due housekeeping."""
        now = time.monotonic()
        timeout = max(0.0, min(max_wait_s, self._next_tick_s - now))
        if self._streams is not None:
            timeout = min(timeout, self._stream_poll_s)
        sources: list[Any] = [self.waker, *self.links.all()]
        ready, _, _ = select.select(sources, [], [], timeout)
        now = time.monotonic()
        received: list[tuple[Link, list[tuple[Msg, tuple[str, int]]]]] = []
        for source in ready:
            if source is self.waker:
                self.waker.drain()
            else:
                received.append((source, source.receive(now)))
        if self._dormant and any(msgs for _, msgs in received):
            self._drain_inbox(now)  # someone speaks: the newest states before answering
        for link, msgs in received:
            for msg, addr in msgs:
                self._dispatch(link, msg, addr, now)
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
        ticks: list[TickView] = []
        self._take_streams(latest, ticks, now)
        # Status first (telemetry for a state carries the newest status), and bus data before
        # command completions: the autopilot publishes its status before it replies, so an
        # ACK never goes out while the gateway still holds the status from before the command.
        for kind in (KIND_STATUS, KIND_READING):
            for (k, vid), payload in latest.items():
                if k == kind:
                    self._on_bus_safely(kind, self.vehicles[vid], payload, now)
        if ticks:
            try:
                self.feed.on_ticks(ticks, now)
            except Exception:  # garbage on sim/tick must never end the gateway
                log.exception("error handling %d ticks", len(ticks))
        for call in calls:
            try:
                call()
            except Exception:
                log.exception("error in a command completion")

    def _take_streams(
        self, latest: dict[tuple[str, str], bytes], ticks: list[TickView], now: float
    ) -> None:
        """Every tick and the newest readings while someone listens on a link. While nobody
        does (dormant), only the newest tick, a few times a second (the vehicles' states stay
        current for commands), and no readings: they are for telemetry only, and the bus
        stops sending them here (at many vehicles they are most of the gateway's traffic)."""
        streams = self._streams
        if streams is None:
            return
        self._dormant = not self.links.listened(now)
        if not self._dormant:
            streams.resume_readings()
            flowing = streams.drain(latest, ticks) > 0
            self._stream_poll_s = STREAM_POLL_S if flowing else STREAM_IDLE_POLL_S
            return
        streams.pause_readings()
        newest = streams.newest_tick()
        if newest is not None:
            ticks.append(newest)
        self._stream_poll_s = STREAM_IDLE_POLL_S

    def _tick(self, now: float) -> None:
        """Wall-clock housekeeping: heartbeats, upload timeouts, parameter sync."""
        if now >= self._next_heartbeat_s:
            period = HEARTBEAT_PERIOD_S
            late = now - self._next_heartbeat_s > period
            self._next_heartbeat_s = now + period if late else self._next_heartbeat_s + period
            self.feed.beat(now)
        for v in self.vehicles.values():
            self.missions.on_timer(v, now)
            self.params.sync(v, now)

    # ------------------------------------------------------------------ bus data
    def _on_bus_safely(self, kind: str, v: Vehicle, payload: bytes, now: float) -> None:
        try:
            self._on_bus(kind, v, payload, now)
        except Exception:
            log.exception("error handling %s of %s", kind, v.id)

    def _on_bus(self, kind: str, v: Vehicle, payload: bytes, now: float) -> None:
        if kind != KIND_STATUS:
            v.feed_reading(payload)  # decoded when telemetry needs it
            return
        status = decode_or_none(payload, VehicleStatus, v.status_label, log)
        if status is not None and status.vehicle_id == v.id:
            self.feed.on_status(v, status, now)
            self.params.sync(v, now)

    # ------------------------------------------------------------------ MAVLink in
    def _handle(self, link: Link, msg: Msg, addr: tuple[str, int], now: float) -> None:
        kind = msg.get_type()
        src = int(msg.get_srcSystem())
        if src in self.by_sysid:
            return  # one of our own vehicles echoed back (a forwarding client): never a GCS
        peer = ms.Peer(link.name, addr, src, int(msg.get_srcComponent()))
        if kind == "HEARTBEAT":
            self.gcs.on_heartbeat(link, now)
            return
        handler = self._handlers.get(kind)
        if handler is None:
            return
        for v in self._targets(link, msg):
            handler(link, v, msg, peer, now)

    def _targets(self, link: Link, msg: Msg) -> list[Vehicle]:
        """Vehicles of ``link`` a message is addressed to; others ignore it (QGC's UDP link
        writes every packet to every vehicle it heard)."""
        if msg.get_type() == "FOLLOW_TARGET":  # addressed to nobody: whoever follows
            following = (self.by_sysid[s] for s in link.sysids)
            return [v for v in following if v.status is not None and v.status.mode == "follow"]
        system = getattr(msg, "target_system", getattr(msg, "target", None))  # MANUAL_CONTROL
        component = getattr(msg, "target_component", 0)
        if system is None or component not in (0, 1):
            return []
        if system == 0:
            return [self.by_sysid[s] for s in link.sysids]
        if system in link.sysids:
            return [self.by_sysid[system]]
        return []


def main(ctx: NodeContext) -> int:
    """Run the gateway for ``ctx.vehicle_ids`` (default: every vehicle of the scenario)."""
    try:
        options = role_options(GatewayOptions, ctx)
        options.rates_hz(), signing_key(ctx.scenario.gateway)  # refused before joining the bus
    except OptionError as exc:
        log.error("gateway: %s", exc)
        return 2
    ids = list(ctx.vehicle_ids) or [v.id for v in ctx.scenario.vehicles]
    with NodeRuntime(ctx, role="gateway") as rt:
        try:
            gateway = Gateway(ctx.scenario, options, ids, rt.session, rt.keys)
        except OSError as exc:
            log.error("gateway: cannot open its UDP ports: %s", exc)
            return 2
        except OptionError as exc:
            log.error("gateway: %s", exc)
            return 2
        with gateway:
            rt.ready()
            gateway.run(rt.stop)
    return 0
