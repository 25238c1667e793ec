"""The architecture's own ceiling: stand-ins for the roles (``ceiling-physics``,
``ceiling-autopilot``, ``ceiling-plume``, ``ceiling-gateway``) that do no work but the lockstep
handshake, with messages of the real sizes. See docs/performance.md ("The ceiling").
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterable, Mapping, Sequence

import zenoh

from swarmbus.codec import decode_or_none, encode
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Clock,
    ConcentrationReading,
    FieldSample,
    FlightMode,
    PeerReading,
    PlumeSample,
    SimTick,
    SpeedMode,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.session import SINGLE_THREAD_RUNTIME, Presence
from swarmbus.views import BatchView, TickView

log = logging.getLogger(__name__)

CLOCK_PERIOD_S = 0.1
STATUS_PERIOD_S = 0.5
ROTORS = 4


def answer_ticks(
    session: zenoh.Session,
    keys: Keys,
    node_name: str,
    rotors: Mapping[str, Sequence[float]],
    then: Callable[[int], None] | None = None,
) -> zenoh.Subscriber[None]:
    """Answer every ``sim/tick`` (in the callback) with one batch of ``rotors`` (vehicle →
    rotor commands) on ``node_name``'s actuator key, then call ``then(tick)``."""
    pub = session.declare_publisher(keys.autopilot_actuators(node_name))

    def on_tick(sample: zenoh.Sample) -> None:
        decoded = decode_or_none(
            sample.payload.to_bytes(), TickView, "a tick", log, str(sample.key_expr)
        )
        if decoded is None:
            return
        tick = decoded.tick
        commands = [
            ActuatorCommand(vehicle_id=v, tick=tick, rotor_commands=list(u))
            for v, u in rotors.items()
        ]
        pub.put(encode(ActuatorBatch(tick=tick, commands=commands)))
        if then is not None:
            then(tick)

    return session.declare_subscriber(keys.tick(), on_tick)


def participant_tokens(
    session: zenoh.Session, keys: Keys, vehicle_ids: Iterable[str], node_name: str = ""
) -> list[zenoh.LivelinessToken]:
    """One lockstep participant token per vehicle (``node_name``'s own runtime declares its)."""
    return [
        session.liveliness().declare_token(keys.node_health(autopilot_node(v)))
        for v in vehicle_ids
        if autopilot_node(v) != node_name
    ]


def _state(vid: str) -> VehicleState:
    return VehicleState(
        vehicle_id=vid,
        tick=0,
        sim_time_s=0.0,
        position_enu_m=(0.0, 0.0, 0.0),
        velocity_enu_m_s=(0.0, 0.0, 0.0),
        attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
        body_rates_rad_s=(0.0, 0.0, 0.0),
        lat_deg=0.0,
        lon_deg=0.0,
        alt_m=0.0,
        on_ground=True,
    )


def _sensor_period(ctx: NodeContext) -> int:
    return ctx.scenario.sensor.resolved().period_ticks


# ---------------------------------------------------------------------------- physics
class _Barrier:
    """Counts the answers of the current tick: one command per vehicle (in batches), and the
    plume's sample on a sensor tick it waits for."""

    def __init__(self, keys: Keys, vehicles: int) -> None:
        self.keys = keys
        self.vehicles = vehicles
        self.cond = threading.Condition()
        self.tick = 0
        self.answered = 0
        self.expected = vehicles

    def on_batch(self, sample: zenoh.Sample) -> None:
        view = decode_or_none(
            sample.payload.to_bytes(), BatchView, "an actuator batch", log, str(sample.key_expr)
        )
        if view is None:
            return
        with self.cond:
            if view.tick == self.tick:
                self.answered += len(view.commands)
                if self.answered >= self.expected:
                    self.cond.notify()

    def on_sample(self, sample: zenoh.Sample) -> None:
        decoded = decode_or_none(
            sample.payload.to_bytes(), FieldSample, "a plume sample", log, str(sample.key_expr)
        )
        if decoded is None:
            return
        tick = decoded.tick
        with self.cond:
            if tick == self.tick and self.expected > self.vehicles:
                self.answered += 1
                if self.answered >= self.expected:
                    self.cond.notify()

    def wait(self, stop: threading.Event) -> bool:
        with self.cond:
            while self.answered < self.expected:
                if stop.is_set():
                    return False
                self.cond.wait(0.25)
            return True

    def next(self, tick: int, plume: bool) -> None:
        with self.cond:
            self.tick = tick
            self.answered = 0
            self.expected = self.vehicles + plume


def physics_main(ctx: NodeContext) -> int:
    """Stand-in for the physics: the tick loop with no world behind it."""
    sc = ctx.scenario
    keys = Keys(sc.world.name)
    ids = [v.id for v in sc.vehicles]
    states = [_state(v) for v in ids]
    dt = 1.0 / sc.time.control_hz
    period = _sensor_period(ctx)
    with NodeRuntime(ctx, role="physics") as rt:
        session = rt.session
        barrier = _Barrier(keys, len(ids))
        subs = [
            session.declare_subscriber(keys.all_autopilot_actuators(), barrier.on_batch),
            session.declare_subscriber(keys.plume_sample(), barrier.on_sample),
        ]
        tick_pub = session.declare_publisher(keys.tick())
        sensor_pub = session.declare_publisher(keys.sensor_tick())
        clock_pub = session.declare_publisher(keys.clock())
        presence = Presence(session, keys)
        presence.sync()
        wanted = {autopilot_node(v) for v in ids}
        if not presence.wait_for(lambda alive: wanted <= alive, sc.time.startup_timeout_s):
            log.error("ceiling-physics: autopilot stand-ins missing: %s", wanted - presence.alive)
            return 1
        plume = "plume" in presence.alive
        rt.ready()
        sample: PlumeSample | None = None  # what the next tick carries
        values = [0.0] * len(ids)

        tick = 0
        wall0 = clock_wall = time.monotonic()
        while not rt.stop.is_set():
            queried = plume and tick % period == 0
            barrier.next(tick, queried)
            payload = encode(
                SimTick(
                    tick=tick,
                    sim_time_s=tick * dt,
                    control_dt_s=dt,
                    states=states,
                    plume_queried=queried,
                    plume_values=sample,
                )
            )
            tick_pub.put(payload)
            if tick % period == 0:
                sensor_pub.put(payload)
            if not barrier.wait(rt.stop):
                break
            sample = PlumeSample(tick=tick, values_g_m3=values) if queried else None
            tick += 1
            now = time.monotonic()
            if now - clock_wall >= CLOCK_PERIOD_S:
                clock_wall = now
                clock_pub.put(
                    encode(
                        Clock(
                            tick=tick,
                            sim_time_s=tick * dt,
                            mode=SpeedMode.LOCKSTEP,
                            speed_factor=1.0,
                            real_time_factor=tick * dt / max(now - wall0, 1e-9),
                        )
                    )
                )
        for sub in subs:
            sub.undeclare()
        presence.close()
    return 0


# ---------------------------------------------------------------------------- autopilot
def autopilot_main(ctx: NodeContext) -> int:
    """Stand-in for an autopilot process serving ``ctx.vehicle_ids``."""
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)  # as the autopilot
    sc = ctx.scenario
    keys = Keys(sc.world.name)
    served = list(ctx.vehicle_ids)
    others = [v.id for v in sc.vehicles]
    period = _sensor_period(ctx)
    readings = {
        vid: encode(
            ConcentrationReading(
                vehicle_id=vid,
                sim_time_s=0.0,
                position_enu_m=(0.0, 0.0, 0.0),
                available=True,
                reported_g_m3=0.0,
                true_g_m3=0.0,
                peers=[
                    PeerReading(vehicle_id=p, position_enu_m=(0.0, 0.0, 0.0), true_g_m3=0.0)
                    for p in others
                    if p != vid
                ],
            )
        )
        for vid in served
    }
    statuses = {
        vid: encode(
            VehicleStatus(
                vehicle_id=vid, sim_time_s=0.0, mode=FlightMode.DISARMED, armed=False, landed=True
            )
        )
        for vid in served
    }
    with NodeRuntime(ctx, role="autopilot") as rt:
        session = rt.session
        reading_pubs = {v: session.declare_publisher(keys.vehicle_concentration(v)) for v in served}
        status_pubs = {v: session.declare_publisher(keys.vehicle_status(v)) for v in served}

        def after(tick: int) -> None:
            if tick % period == 0:
                for vid, pub in reading_pubs.items():
                    pub.put(readings[vid])

        rotors = {v: [0.0] * ROTORS for v in served}
        sub = answer_ticks(session, keys, ctx.name, rotors, after)
        tokens = participant_tokens(session, keys, served, ctx.name)
        rt.ready()
        while not rt.stop.wait(STATUS_PERIOD_S):
            for vid, pub in status_pubs.items():
                pub.put(statuses[vid])
        sub.undeclare()
        for token in tokens:
            token.undeclare()
    return 0


# ---------------------------------------------------------------------------- plume, gateway
def plume_main(ctx: NodeContext) -> int:
    """Stand-in for the plume service: a sample of N values for every sensor tick."""
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)  # as the plume
    keys = Keys(ctx.scenario.world.name)
    values = [0.0] * len(ctx.scenario.vehicles)
    with NodeRuntime(ctx, role="plume") as rt:
        pub = rt.session.declare_publisher(keys.plume_sample())

        def on_tick(sample: zenoh.Sample) -> None:
            view = decode_or_none(
                sample.payload.to_bytes(), TickView, "a tick", log, str(sample.key_expr)
            )
            if view is None:
                return
            answer = FieldSample(tick=view.tick, sim_time_s=view.sim_time_s, values_g_m3=values)
            pub.put(encode(answer))

        sub = rt.session.declare_subscriber(keys.sensor_tick(), on_tick)
        rt.ready()
        rt.stop.wait()
        sub.undeclare()
    return 0


def gateway_main(ctx: NodeContext) -> int:
    """Stand-in for the MAVLink gateway: takes what the gateway takes off the bus, drops it."""
    keys = Keys(ctx.scenario.world.name)

    def drop(sample: zenoh.Sample) -> None:
        sample.payload.to_bytes()

    with NodeRuntime(ctx, role="gateway") as rt:
        subs = [
            rt.session.declare_subscriber(k, drop)
            for k in (keys.tick(), keys.all_vehicle_status(), keys.all_vehicle_concentration())
        ]
        rt.ready()
        rt.stop.wait()
        for s in subs:
            s.undeclare()
    return 0
