"""The ``ros2`` role: the run as ROS 2 topics on the same Zenoh, in rmw_zenoh's wire format
(:mod:`ros2_bridge.wire`), so ROS 2 nodes on ``rmw_zenoh_cpp`` see a node ``/plumeswarm`` with
its publishers and subscriptions in ``ros2 node list`` and ``ros2 topic list``.

A passive client of the bus, like the viewers: it takes part in no lockstep. Each bus stream it
reads (``sim/tick``, the readings, the anemometers, ``field/state``) is subscribed only while a
ROS 2 subscriber matches one of the topics made from it (Zenoh's matching listeners of the ROS
publishers), so with no ROS 2 subscriber Zenoh sends it nothing, nothing is encoded and the loop
sleeps. Zenoh callbacks only keep the newest payload; the loop converts and publishes at most
``rate_hz`` times a second (``/clock``, ``/tf``, odometry, fixes; the newest reading of each
vehicle) and the plume markers every ``markers_period_s``.

``/<vehicle>/cmd_vel`` (geometry_msgs/Twist in the vehicle's body frame) becomes the vehicle's
offboard velocity ``Setpoint``, sent as a bus command (``vehicle/<id>/cmd``), one at a time per
vehicle, the newest replacing one waiting; the autopilot's offboard failsafe acts when the
stream stops (``[failsafe] offboard_timeout_s``), as PX4's does. A payload that is not a
Twist is dropped with a log line.

Options (``--set KEY=VALUE``): ``domain_id`` (0; also ``ROS_DOMAIN_ID``), ``rate_hz`` (50),
``markers_period_s`` (2), ``node_name`` (``plumeswarm``).
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Annotated, Any

import msgspec
import zenoh

from ros2_bridge import convert as cv
from ros2_bridge import wire
from swarmbus.codec import decode_or_none
from swarmbus.keys import Keys
from swarmbus.messages import (
    AnemometerReading,
    Clock,
    CommandReply,
    ConcentrationReading,
    PlumeMesh,
    PlumeState,
    Setpoint,
    SimTick,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, RoleOptions, role_options
from swarmbus.reqrep import RequestError, ask
from swarmbus.session import payload_or_none
from swarmbus.view_feed import MeshFetcher, isosurface_queries

log = logging.getLogger(__name__)

HEALTH_PERIOD_S = 1.0
COMMAND_TIMEOUT_S = 2.0
STEER_HOLD_S = 2.0  # after a cmd_vel, keep following the vehicles' headings this long
MAX_DOMAIN_ID = 232  # ROS 2's largest domain id


class BridgeOptions(RoleOptions, frozen=True, kw_only=True):
    """The ros2 role's options (``--set KEY=VALUE``)."""

    domain_id: Annotated[int, msgspec.Meta(ge=0, le=MAX_DOMAIN_ID)] | None = None
    rate_hz: Annotated[float, msgspec.Meta(ge=0.1, le=1000.0)] = 50.0
    markers_period_s: Annotated[float, msgspec.Meta(ge=0.1, le=3600.0)] = 2.0
    node_name: Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z][A-Za-z0-9_]{0,63}$")] = "plumeswarm"


def domain_id(opts: BridgeOptions) -> int:
    """The option, else ``ROS_DOMAIN_ID`` (as every ROS 2 node reads it), else 0."""
    if opts.domain_id is not None:
        return opts.domain_id
    raw = os.environ.get("ROS_DOMAIN_ID", "").strip()
    if not raw:
        return 0
    if not raw.isdigit() or int(raw) > MAX_DOMAIN_ID:
        raise OptionError(f"ROS_DOMAIN_ID={raw!r}: not a domain id 0..{MAX_DOMAIN_ID}")
    return int(raw)


class RosPublisher:
    """One ROS 2 publisher: its token, its Zenoh publisher, its sequence numbers. Whether a
    subscriber is there is kept up to date by Zenoh's matching listener, which also sets
    ``changed`` (the loop sleeps on it while nobody listens)."""

    def __init__(
        self,
        session: zenoh.Session,
        graph: wire.Graph,
        topic: str,
        msgtype: str,
        changed: threading.Event,
    ):
        self.topic = topic
        self.msgtype = msgtype
        self._pub = session.declare_publisher(wire.topic_key(graph.node.domain_id, topic, msgtype))
        self._gid = graph.declare_entity("MP", topic, msgtype)
        self._sequence = 0
        self._changed = changed
        self.wanted = False  # a ROS 2 subscriber (or any Zenoh subscriber of its key) is there
        self._listener = self._pub.declare_matching_listener(self._on_matching)
        status: object = self._pub.matching_status  # a subscriber already there (the stubs: bool)
        self.wanted = self.wanted or bool(getattr(status, "matching", status))
        self.sent = 0

    def _on_matching(self, status: zenoh.MatchingStatus) -> None:
        self.wanted = bool(status.matching)
        self._changed.set()

    def publish(self, message: Any) -> None:
        """Sequence numbers start at 1; the source timestamp is the wall clock's, as
        rmw_zenoh's (the messages' own stamps are sim time)."""
        self._sequence += 1
        self._pub.put(
            wire.encode(message, self.msgtype),
            attachment=wire.attachment(self._sequence, time.time_ns(), self._gid),
        )
        self.sent += 1

    def close(self) -> None:
        self._listener.undeclare()
        self._pub.undeclare()


class Latest:
    """A bus stream subscribed only while wanted; the callback keeps the newest payload per
    key."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self._session = session
        self._key = key
        self._lock = threading.Lock()
        self._latest: dict[str, bytes] = {}
        self._sub: zenoh.Subscriber[None] | None = None

    def want(self, wanted: bool) -> None:
        if wanted and self._sub is None:
            self._sub = self._session.declare_subscriber(self._key, self._on_sample)
        elif not wanted and self._sub is not None:
            self._sub.undeclare()
            self._sub = None
            self.take()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "a message", log)
        if data is None:
            return
        with self._lock:
            self._latest[str(sample.key_expr)] = data

    def take(self) -> dict[str, bytes]:
        with self._lock:
            out, self._latest = self._latest, {}
        return out

    def close(self) -> None:
        self.want(False)


class SetpointSender:
    """One vehicle's setpoints to its autopilot: one query at a time, the newest waiting."""

    def __init__(self, session: zenoh.Session, keys: Keys, vehicle_id: str) -> None:
        self._session = session
        self._key = keys.vehicle_cmd(vehicle_id)
        self._vehicle_id = vehicle_id
        self._lock = threading.Lock()
        self._busy = False
        self._waiting: Setpoint | None = None
        self._last_refusal = ""
        self.sent = 0

    def send(self, setpoint: Setpoint) -> None:
        with self._lock:
            if self._busy:
                self._waiting = setpoint
                return
            self._busy = True
        self._ask(setpoint)

    def _ask(self, setpoint: Setpoint) -> None:
        self.sent += 1
        ask(self._session, self._key, setpoint, CommandReply, COMMAND_TIMEOUT_S, self._done)

    def _done(self, outcome: CommandReply | RequestError) -> None:
        refusal = ""
        if isinstance(outcome, RequestError):
            refusal = str(outcome)
        elif not outcome.accepted:
            refusal = f"{outcome.code}: {outcome.reason}"
        if refusal and refusal != self._last_refusal:
            log.warning("ros2: %s cmd_vel setpoint not taken: %s", self._vehicle_id, refusal)
        self._last_refusal = refusal
        with self._lock:
            nxt, self._waiting = self._waiting, None
            if nxt is None:
                self._busy = False
                return
        self._ask(nxt)


class CmdVel:
    """``/<vehicle>/cmd_vel`` subscriptions → setpoints."""

    def __init__(
        self,
        session: zenoh.Session,
        graph: wire.Graph,
        keys: Keys,
        vehicle_ids: list[str],
        state_of: Callable[[str], VehicleState | None],
        arrived: threading.Event,
    ) -> None:
        self._state_of = state_of
        self._arrived = arrived
        self._senders = {vid: SetpointSender(session, keys, vid) for vid in vehicle_ids}
        self._subs: list[zenoh.Subscriber[None]] = []
        self.last_s = -1e9
        self.rejected = 0
        for vid in vehicle_ids:
            topic = f"/{vid}/cmd_vel"
            graph.declare_entity("MS", topic, cv.TWIST)
            key = wire.topic_key(graph.node.domain_id, topic, cv.TWIST)
            self._subs.append(session.declare_subscriber(key, partial(self._on_twist, vid)))

    def _on_twist(self, vehicle_id: str, sample: zenoh.Sample) -> None:
        self.last_s = time.monotonic()
        self._arrived.set()
        payload = payload_or_none(sample, "a Twist", log)
        if payload is None:
            return
        try:
            twist = wire.decode(payload, cv.TWIST)
            if len(wire.encode(twist, cv.TWIST)) != len(payload):
                raise wire.WireError(f"{len(payload)} bytes, a Twist is 52")
            state = self._state_of(vehicle_id)
            setpoint = cv.setpoint_of(twist, state) if state is not None else None
        except (wire.WireError, ValueError) as exc:
            self.rejected += 1
            log.warning("ros2: /%s/cmd_vel: rejected payload: %s", vehicle_id, exc)
            return
        if setpoint is None:  # the first after a pause: the vehicle's heading comes with a tick
            log.debug("ros2: /%s/cmd_vel: no state yet, setpoint dropped", vehicle_id)
            return
        self._senders[vehicle_id].send(setpoint)

    @property
    def sent(self) -> int:
        return sum(s.sent for s in self._senders.values())

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


class Bridge:
    """The ROS 2 node's publishers and the bus streams they are made from."""

    def __init__(self, rt: NodeRuntime, opts: BridgeOptions, domain: int) -> None:
        self.rt = rt
        self.opts = opts
        session, sc = rt.session, rt.ctx.scenario
        self.scenario = sc
        self.vehicle_ids = [v.id for v in sc.vehicles]
        node = wire.NodeName(domain, str(session.info.zid()), 0, opts.node_name)
        self.graph = wire.Graph(session, node)
        self.changed = threading.Event()  # a subscriber came or went, or a cmd_vel arrived
        self.pubs = {
            topic: RosPublisher(session, self.graph, topic, msgtype, self.changed)
            for topic, msgtype in cv.topics(self.vehicle_ids).items()
        }
        keys = rt.keys
        self.ticks = Latest(session, keys.tick())
        self.clock = Latest(session, keys.clock())  # the markers' stamps, when ticks are off
        self.readings = Latest(session, keys.all_vehicle_concentration())
        self.winds = Latest(session, keys.all_vehicle_wind())
        self.plume_state = Latest(session, keys.plume_state())
        self._states: dict[str, VehicleState] = {}
        self._states_lock = threading.Lock()
        self.cmd_vel = CmdVel(
            session, self.graph, keys, self.vehicle_ids, self.state_of, self.changed
        )
        self._meshes: MeshFetcher | None = None
        self._mesh_list: dict[int, PlumeMesh] = {}
        self._newest_state: PlumeState | None = None
        self._sim_time_s = 0.0
        self.graph.declare_node()

    def state_of(self, vehicle_id: str) -> VehicleState | None:
        with self._states_lock:
            return self._states.get(vehicle_id)

    def _wanted(self, *topics: str) -> bool:
        return any(self.pubs[t].wanted for t in topics)

    def _per_vehicle(self, leaf: str) -> list[str]:
        return [f"/{vid}/{leaf}" for vid in self.vehicle_ids]

    def gate(self) -> bool:
        """Subscribe each bus stream while a ROS 2 subscriber wants something made of it;
        whether anything is wanted."""
        steering = time.monotonic() - self.cmd_vel.last_s < STEER_HOLD_S
        tick_topics = ["/clock", "/tf", *self._per_vehicle("odom"), *self._per_vehicle("fix")]
        ticks = steering or self._wanted(*tick_topics)
        self.ticks.want(ticks)
        if not ticks:  # a heading of long ago must not turn the next cmd_vel
            with self._states_lock:
                self._states.clear()
        self.readings.want(self._wanted(*self._per_vehicle("gas")))
        self.winds.want(self._wanted(*self._per_vehicle("wind")))
        markers = self._wanted("/plume/markers")
        self.plume_state.want(markers)
        self.clock.want(markers)
        return steering or self._wanted(*self.pubs)

    def publish_tick(self) -> None:
        raw = self.ticks.take().get(self.rt.keys.tick())
        if raw is None:
            return
        tick = decode_or_none(raw, SimTick, "tick", log)
        if tick is None:
            return
        with self._states_lock:
            self._states.update({s.vehicle_id: s for s in tick.states})
        self._sim_time_s = tick.sim_time_s
        self._put("/clock", partial(cv.clock, tick.sim_time_s))
        self._put("/tf", partial(cv.tf, tick.states))
        for s in tick.states:
            if s.vehicle_id in self.vehicle_ids:
                self._put(f"/{s.vehicle_id}/odom", partial(cv.odometry, s))
                self._put(f"/{s.vehicle_id}/fix", partial(cv.nav_sat_fix, s))

    def _put(self, topic: str, make: Callable[[], Any]) -> None:
        pub = self.pubs[topic]
        if pub.wanted:
            pub.publish(make())

    def publish_readings(self) -> None:
        for key, raw in self.readings.take().items():
            r = decode_or_none(raw, ConcentrationReading, key, log)
            if r is not None and r.vehicle_id in self.vehicle_ids:
                self._put(f"/{r.vehicle_id}/gas", partial(cv.gas, r))
        for key, raw in self.winds.take().items():
            w = decode_or_none(raw, AnemometerReading, key, log)
            if w is not None and w.vehicle_id in self.vehicle_ids:
                self._put(f"/{w.vehicle_id}/wind", partial(cv.wind, w))

    def publish_markers(self) -> None:
        pub = self.pubs["/plume/markers"]
        if not pub.wanted:
            return
        raw_clock = self.clock.take().get(self.rt.keys.clock())
        clock = None if raw_clock is None else decode_or_none(raw_clock, Clock, "clock", log)
        if clock is not None:
            self._sim_time_s = max(self._sim_time_s, clock.sim_time_s)
        if self._meshes is None:  # asked once somebody wants the markers
            queries = isosurface_queries(self.scenario)
            self._meshes = MeshFetcher(self.rt.session, self.rt.keys, queries)
        self._mesh_list.update(self._meshes.take())
        raw = self.plume_state.take().get(self.rt.keys.plume_state())
        if raw is not None:
            self._newest_state = (
                decode_or_none(raw, PlumeState, "plume state", log) or self._newest_state
            )
        meshes = [self._mesh_list[i] for i in sorted(self._mesh_list)]
        msg = cv.markers(self.scenario, self._sim_time_s, meshes, self._newest_state)
        pub.publish(msg)

    def detail(self) -> str:
        sent = sum(p.sent for p in self.pubs.values())
        return (
            f"domain={self.graph.node.domain_id} sent={sent} cmd_vel={self.cmd_vel.sent} "
            f"rejected={self.cmd_vel.rejected}"
        )

    def close(self) -> None:
        for stream in (self.ticks, self.clock, self.readings, self.winds, self.plume_state):
            stream.close()
        if self._meshes is not None:
            self._meshes.close()
        self.cmd_vel.close()
        self.graph.close()
        for pub in self.pubs.values():
            pub.close()


def run(bridge: Bridge) -> None:
    """Convert and publish at most ``rate_hz`` times a second while anything is wanted; while
    nothing is, sleep until a subscriber or a cmd_vel comes (or the health beat)."""
    rt, opts = bridge.rt, bridge.opts
    period = 1.0 / opts.rate_hz
    next_health = next_markers = time.monotonic()
    while not rt.stop.is_set():
        t0 = time.monotonic()
        bridge.changed.clear()
        busy = bridge.gate()
        if busy:
            bridge.publish_tick()
            bridge.publish_readings()
            if t0 >= next_markers:
                next_markers = t0 + opts.markers_period_s
                bridge.publish_markers()
        if t0 >= next_health:
            next_health = t0 + HEALTH_PERIOD_S
            rt.publish_health(sim_time_s=bridge._sim_time_s, detail=bridge.detail())
        if busy:
            rt.stop.wait(max(0.0, period - (time.monotonic() - t0)))
        else:
            bridge.changed.wait(max(0.0, next_health - time.monotonic()))


def main(ctx: NodeContext) -> int:
    try:
        opts = role_options(BridgeOptions, ctx)
        domain = domain_id(opts)
    except OptionError as exc:
        log.error("ros2: %s", exc)
        return 2
    with NodeRuntime(ctx, role="ros2") as rt:
        bridge = Bridge(rt, opts, domain)
        try:
            rt.publish_health(detail=bridge.detail())
            rt.ready()
            log.info(
                "ros2: node /%s on ROS domain %d (rmw_zenoh, ROS 2 %s)",
                opts.node_name, domain, wire.DISTRIBUTION,
            )  # fmt: skip
            run(bridge)
        finally:
            bridge.close()
    return 0
