"""``plumeswarm node gateway``: the MAVLink 2 gateway between ground stations and the bus.

Every vehicle of the scenario that has a sysid is one MAVLink system (its sysid, component 1,
PX4 conventions), reachable on the shared GCS link and on its own API link; MAVLink addresses
systems 1–254 only, so a larger scenario's other vehicles are not served (one line says so).
The gateway talks to autopilots only over the bus contract: it subscribes ``sim/tick`` (every
vehicle's state) and ``vehicle/*/{status,concentration}`` and sends ``Command`` queries to
``vehicle/<id>/cmd``, answering MAVLink with the autopilot's real result.

One thread runs the loop (UDP sockets + a self-pipe woken by Zenoh callbacks), so MAVLink
encoding, sequence numbers and per-vehicle protocol state never race. This module is the loop,
the links, the bus data and telemetry; the microservices' handlers live in ``handle_*.py``.
"""

from __future__ import annotations

import contextlib
import logging
import math
import select
import threading
import time
from types import TracebackType
from typing import Any

import zenoh

from gcs_bridge import mission as ms
from gcs_bridge.bus import (
    KIND_READING,
    KIND_STATUS,
    STREAM_IDLE_POLL_S,
    STREAM_POLL_S,
    Commander,
    Inbox,
    Streams,
    Waker,
    subscribe_statuses,
)
from gcs_bridge.core import Handler
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.handle_commands import GCS_LINK_TIMEOUT_S, CommandHandlers
from gcs_bridge.handle_missions import MissionHandlers
from gcs_bridge.handle_params import ParamHandlers
from gcs_bridge.links import Link
from gcs_bridge.options import GatewayOptions, gateway_options
from gcs_bridge.telemetry import BUILDERS, ID_MISSION_CURRENT, StreamSchedule, wind_enu
from gcs_bridge.vehicle import Vehicle
from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys
from swarmbus.messages import VehicleState, VehicleStatus
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError
from swarmbus.scenario import Scenario, not_on_mavlink_note
from swarmbus.session import Presence
from swarmbus.views import TickView

log = logging.getLogger(__name__)

TICK_S = 0.1  # wall-clock housekeeping: heartbeats, transfer timeouts, parameter sync


class Gateway(CommandHandlers, ParamHandlers, MissionHandlers):
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
        off_mavlink = set(scenario.not_on_mavlink(vehicle_ids))
        if off_mavlink:
            log.warning("%s", not_on_mavlink_note(len(off_mavlink)))
        self.vehicles = {
            vid: Vehicle(scenario, vid, index_of[vid], wind)
            for vid in vehicle_ids
            if vid not in off_mavlink
        }
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
        self._streams: Streams | None = None
        self._stream_poll_s = STREAM_IDLE_POLL_S
        self._fed_sim_s = -math.inf  # sim time of the last tick taken (back: a new simulation)
        self._presence: Presence | None = None
        if session is not None:
            for v in self.vehicles.values():
                self._commanders[v.id] = Commander(
                    session, keys.vehicle_cmd(v.id), v.id, options.cmd_timeout_s, self.inbox
                )
            self._presence = Presence(session, keys)
            self._subs = [subscribe_statuses(session, keys, set(self.vehicles), self.inbox)]
            self._streams = Streams(session, keys, set(self.vehicles))
        self._inflight: set[tuple[int, int, int, int]] = set()
        self._text_budget: dict[tuple[str | None, int], tuple[float, float]] = {}
        self._text_id = 0
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
            "SET_POSITION_TARGET_GLOBAL_INT": self._on_global_target,
            "SET_ATTITUDE_TARGET": self._on_attitude_target,
            "MANUAL_CONTROL": self._on_manual_control,
            "FOLLOW_TARGET": self._on_follow_target,
        }
        self._local_commands = self._command_table()

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
        if self._streams is not None:
            with contextlib.suppress(zenoh.ZError):
                self._streams.undeclare()
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
        if self._streams is not None:
            timeout = min(timeout, self._stream_poll_s)
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
        ticks: list[TickView] = []
        if self._streams is not None:
            flowing = self._streams.drain(latest, ticks) > 0
            self._stream_poll_s = STREAM_POLL_S if flowing else STREAM_IDLE_POLL_S
        # Status first (telemetry for a state carries the newest status), and bus data before
        # command completions: the autopilot publishes its status before it replies, so an
        # ACK never goes out while the gateway still holds the status from before the command.
        for kind in (KIND_STATUS, KIND_READING):
            for (k, vid), payload in latest.items():
                if k == kind:
                    self._on_bus_safely(kind, self.vehicles[vid], payload, now)
        if ticks:
            try:
                self._on_ticks(ticks, now)
            except Exception:  # garbage on sim/tick must never end the gateway
                log.exception("error handling %d ticks", len(ticks))
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

    # ------------------------------------------------------------------ bus data
    def _on_bus_safely(self, kind: str, v: Vehicle, payload: bytes, now: float) -> None:
        try:
            self._on_bus(kind, v, payload, now)
        except Exception:
            log.exception("error handling %s of %s", kind, v.id)

    def _window(self, v: Vehicle, now: float, names: frozenset[str]) -> tuple[float, float]:
        """``(lo, hi)``: nothing is due for ``v`` at a sim time t with lo <= t < hi (then its
        state need not even be decoded); a superset of the times something may be due."""
        if not self.alive_in(v, now, names):
            return -math.inf, math.inf
        lo, hi = -math.inf, math.inf
        for link in self.links_of[v.sysid]:
            schedule = self.schedules[(link.name, v.sysid)]
            lo = max(lo, schedule.lo - 1e-6)
            hi = min(hi, schedule.hi - 1e-9)
            if now - link.gcs_heard_s <= GCS_LINK_TIMEOUT_S:  # the GCS link keep-alive
                hi = min(hi, v.last_gcs_heartbeat_sim_s + 1.0 - 1e-6)
        return lo, hi

    def _on_ticks(self, ticks: list[TickView], now: float) -> None:
        """Every tick's sim time against each vehicle's window; a vehicle's state is decoded
        and handled only where its telemetry (or keep-alive) falls due. The newest tick's
        states are left with the vehicles, decoded only if something reads them."""
        assert self._streams is not None
        streams = self._streams
        vehicles = list(self.vehicles.values())
        names = self._presence.alive if self._presence is not None else frozenset()
        windows = {v.id: self._window(v, now, names) for v in vehicles}
        lo_all = max((w[0] for w in windows.values()), default=-math.inf)
        hi_all = min((w[1] for w in windows.values()), default=math.inf)
        last = ticks[-1]
        for view in ticks:
            t = view.sim_time_s
            if t < self._fed_sim_s:  # a new simulation
                for v in vehicles:
                    v.last_gcs_heartbeat_sim_s = -1e9
                    windows[v.id] = self._window(v, now, names)
                lo_all = max((w[0] for w in windows.values()), default=-math.inf)
                hi_all = min((w[1] for w in windows.values()), default=math.inf)
            self._fed_sim_s = t
            if view is last:
                for v in vehicles:
                    raw = streams.raw_state(view, v.id)
                    if raw is not None:
                        v.feed_state(raw)
            if lo_all <= t < hi_all:
                continue
            for v in vehicles:
                lo, hi = windows[v.id]
                if lo <= t < hi:
                    continue
                self._on_state_raw(view, v, now)
                windows[v.id] = self._window(v, now, names)
            lo_all = max((w[0] for w in windows.values()), default=-math.inf)
            hi_all = min((w[1] for w in windows.values()), default=math.inf)

    def _on_state_raw(self, view: TickView, v: Vehicle, now: float) -> None:
        assert self._streams is not None
        for attempt in range(2):
            raw = self._streams.raw_state(view, v.id)
            if raw is None:
                return
            try:
                state = decode(memoryview(raw), VehicleState)
            except MessageError as exc:
                log.warning("state of %s: %s", v.id, exc)
                return
            if state.vehicle_id == v.id:
                try:
                    self._on_state(v, state, now)
                except Exception:
                    log.exception("error handling the state of %s", v.id)
                return
            if attempt or not self._streams.learn(view):  # the tick's layout changed
                return

    def _on_bus(self, kind: str, v: Vehicle, payload: bytes, now: float) -> None:
        try:
            if kind == KIND_STATUS:
                status = decode(payload, VehicleStatus)
                if status.vehicle_id == v.id:
                    self._on_status(v, status, now)
            else:
                v.feed_reading(payload)  # decoded when telemetry needs it
        except MessageError as exc:
            log.warning("%s of %s: %s", kind, v.id, exc)

    def _on_state(self, v: Vehicle, state: VehicleState, now: float) -> None:
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
        options = gateway_options(ctx.scenario.gateway, ctx.options)
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
        with gateway:
            rt.ready()
            gateway.run(rt.stop)
    return 0
