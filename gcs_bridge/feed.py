"""Telemetry: the bus's vehicle data in (ticks, statuses, readings), MAVLink streams out.

Every tick's sim time is compared with each vehicle's window (when none of its streams is due
on any of its links); a vehicle's state is decoded and its telemetry built only where something
falls due, and each message is built once for all the links it goes to. The newest tick's
states are left with the vehicles, decoded only if something reads them.

Nothing is built for a link where nobody listens (:meth:`gcs_bridge.links.Link.listened`): its
streams wait, and start again from the newest state once someone is there.
"""

from __future__ import annotations

import dataclasses
import logging
import math

from gcs_bridge.bus import Streams
from gcs_bridge.core import Autopilots, Outbox
from gcs_bridge.dialect import Msg, mavlink
from gcs_bridge.handle_commands import GcsHeartbeats
from gcs_bridge.links import LinkSet
from gcs_bridge.telemetry import BUILDERS, ID_MISSION_CURRENT
from gcs_bridge.vehicle import Vehicle
from swarmbus.codec import decode_or_none
from swarmbus.messages import VehicleState, VehicleStatus
from swarmbus.views import TickView

log = logging.getLogger(__name__)

Window = tuple[float, float]
ALWAYS_QUIET: Window = (-math.inf, math.inf)


@dataclasses.dataclass(eq=False)
class TelemetryFeed:
    """Each vehicle's telemetry streams on each of its links, fed by ticks and statuses."""

    vehicles: list[Vehicle]
    links: LinkSet
    out: Outbox
    autopilots: Autopilots
    gcs: GcsHeartbeats
    streams: Streams | None
    # sim time of the last tick taken (back: a new simulation)
    _fed_sim_s: float = dataclasses.field(default=-math.inf, init=False)

    # ------------------------------------------------------------------ heartbeats
    def beat(self, now: float) -> None:
        """HEARTBEAT of every vehicle whose autopilot is there (wall-clock period)."""
        for v in self.vehicles:
            if self.autopilots.alive(v, now):
                self.out.send_all(v, v.heartbeat(), now)

    # ------------------------------------------------------------------ ticks
    def _window(self, v: Vehicle, now: float, names: frozenset[str]) -> Window:
        """``(lo, hi)``: nothing is due for ``v`` at a sim time t with lo <= t < hi (then its
        state need not even be decoded); a superset of the times something may be due."""
        if not self.autopilots.alive_in(v, now, names):
            return ALWAYS_QUIET
        lo, hi = -math.inf, math.inf
        for link in self.links.of(v.sysid):
            if self.gcs.heard(link, now):  # the GCS link keep-alive
                hi = min(hi, v.last_gcs_heartbeat_sim_s + 1.0 - 1e-6)
            if not link.listened(now):
                continue
            schedule = self.links.schedule(link, v.sysid)
            lo = max(lo, schedule.lo - 1e-6)
            hi = min(hi, schedule.hi - 1e-9)
        return lo, hi

    def on_ticks(self, ticks: list[TickView], now: float) -> None:
        """Every tick's sim time against each vehicle's window; a vehicle's state is decoded
        and handled only where its telemetry (or keep-alive) falls due."""
        streams = self.streams
        if streams is None:
            return
        names = self.autopilots.names()
        windows = {v.id: self._window(v, now, names) for v in self.vehicles}
        lo_all, hi_all = _common(windows)
        last = ticks[-1]
        for view in ticks:
            t = view.sim_time_s
            if t < self._fed_sim_s:  # a new simulation
                for v in self.vehicles:
                    v.last_gcs_heartbeat_sim_s = -1e9
                    windows[v.id] = self._window(v, now, names)
                lo_all, hi_all = _common(windows)
            self._fed_sim_s = t
            if view is last:
                _leave_states(self.vehicles, streams, view)
            if lo_all <= t < hi_all:
                continue
            for v in self.vehicles:
                lo, hi = windows[v.id]
                if lo <= t < hi:
                    continue
                self._on_state_raw(streams, view, v, now)
                windows[v.id] = self._window(v, now, names)
            lo_all, hi_all = _common(windows)

    def _on_state_raw(self, streams: Streams, view: TickView, v: Vehicle, now: float) -> None:
        for attempt in range(2):
            raw = streams.raw_state(view, v.id)
            if raw is None:
                return
            state = decode_or_none(memoryview(raw), VehicleState, v.state_label, log)
            if state is None:
                return
            if state.vehicle_id == v.id:
                try:
                    self.on_state(v, state, now)
                except Exception:
                    log.exception("error handling the state of %s", v.id)
                return
            if attempt or not streams.learn(view):  # the tick's layout changed
                return

    def on_state(self, v: Vehicle, state: VehicleState, now: float) -> None:
        """A decoded state: the GCS keep-alive, and every stream due on each link."""
        v.state = state
        if not self.autopilots.alive(v, now):
            return
        self.gcs.keep_alive(v, now)
        built: dict[int, Msg | None] = {}
        view = None
        for link in self.links.of(v.sysid):
            if not link.listened(now):
                continue
            for msg_id in self.links.schedule(link, v.sysid).due(state.sim_time_s):
                if msg_id not in built:
                    if msg_id == ID_MISSION_CURRENT:
                        built[msg_id] = v.mission_current_msg()
                    else:
                        view = view or v.view()
                        built[msg_id] = BUILDERS[msg_id](view)
                msg = built[msg_id]
                if msg is not None:
                    link.send(v.sysid, msg, now)

    # ------------------------------------------------------------------ statuses
    def on_status(self, v: Vehicle, status: VehicleStatus, now: float) -> None:
        """What a new status means at once: heartbeat, items reached, current item, home."""
        ev = v.update_status(status, now)
        if ev.heartbeat:
            self.out.send_all(v, v.heartbeat(), now)
        for seq in ev.reached_seqs:
            self.out.send_all(v, mavlink.MAVLink_mission_item_reached_message(seq), now)
        if ev.mission_current:
            self.out.send_all(v, v.mission_current_msg(), now)
        if ev.home_changed:
            home = BUILDERS[mavlink.MAVLINK_MSG_ID_HOME_POSITION](v.view())
            if home is not None:
                self.out.send_all(v, home, now)


def _leave_states(vehicles: list[Vehicle], streams: Streams, view: TickView) -> None:
    """The newest tick's states, still encoded, with their vehicles."""
    for v in vehicles:
        raw = streams.raw_state(view, v.id)
        if raw is not None:
            v.feed_state(raw)


def _common(windows: dict[str, Window]) -> Window:
    """Where every vehicle's window overlaps: nothing is due for anyone there."""
    lo = max((w[0] for w in windows.values()), default=-math.inf)
    hi = min((w[1] for w in windows.values()), default=math.inf)
    return lo, hi
