"""The autopilot process: ``plumeswarm node autopilot --vehicle ID [--vehicle ID2 …]``.

One process serves one vehicle (or a few): it declares one liveliness token
``node/autopilot-<id>/health`` per vehicle (the lockstep's participant list), answers every
``sim/tick`` with an ``ActuatorCommand`` on ``vehicle/<id>/actuators`` — a process serving
several vehicles puts one ``ActuatorBatch`` of all their commands on
``autopilot/<node>/actuators`` instead (one message per process per tick) — serves
``vehicle/<id>/cmd``, publishes ``vehicle/<id>/status`` (on change and every
``status_period_s`` of sim time) and the sensor's ``vehicle/<id>/concentration``.

Ticks are handled in the ``sim/tick`` subscriber's callback, one at a time and in arrival order;
when ticks pile up only the newest is handled (a repeated tick, the start handshake's, gets the
same answer again). The rare tick that has to wait for this process's own plume query (the
physics did not send it) is handed to a worker thread instead of blocking the callback. The
process runs Zenoh on ONE runtime thread (``ZENOH_RUNTIME``, set in :func:`main` unless the
environment sets it): per tick, fewer thread hand-overs and wake-ups — the autopilot's CPU per
tick fell 10–30 % in the scale bench (docs/agents.md, Performance). The sensor's plume query
for tick k (one batched query: every vehicle's position in the tick, i.e. own + peers) is sent
right after tick k's commands and collected before tick k+1's, so its round trip overlaps the
physics step and a behaviour always sees the reading of the previous sensor tick — the same
run after run. When the physics sent that query itself for everyone (``SimTick.plume_queried``),
the autopilot sends none and takes the answer from tick k+1 (``SimTick.plume_values``): the
same values at the same tick. Commands are handled on Zenoh's thread under a lock.

Options (``--set key=value``): ``sensor_timeout_s`` (0: 0.4 × participant timeout),
``status_period_s`` (0.5), ``position_noise_m`` / ``velocity_noise_m_s`` (0: the estimate is
the physics' truth). Plume queries go out only while a ``plume`` node's token is alive.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass, fields
from typing import Any

import msgspec
import numpy as np
import zenoh

from agents.anemometer import Anemometer
from agents.autopilot import Autopilot
from agents.behavior import BehaviorContext, BehaviorError, load_behavior
from agents.estimator import Estimator
from agents.sensor import ConcentrationSensor
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Command,
    ConcentrationReading,
    ErrorReply,
    PeerReading,
    PlumeQuery,
    PlumeSample,
    PlumeValues,
    SimTick,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.scenario import Scenario
from swarmbus.wind import WindModel, wind_from_scenario

log = logging.getLogger(__name__)

# One Zenoh runtime thread for the whole process (receive, send, network, application): a
# tick is received, handled and answered on one thread with no hand-over between threads.
ZENOH_RUNTIME = (
    "(app: (worker_threads: 1), acc: (handover: app), tx: (handover: app),"
    " rx: (handover: app), net: (handover: app))"
)
IDLE_STATUS_PERIOD_S = 1.0  # wall clock: status while no ticks arrive (physics not running)


@dataclass(frozen=True)
class NodeOptions:
    # 0: derived from the scenario, 0.4 × participant_timeout_s (so a slow answer on a loaded
    # machine is still waited for, and the lockstep never drops us for waiting).
    sensor_timeout_s: float = 0.0
    status_period_s: float = 0.5
    position_noise_m: float = 0.0
    velocity_noise_m_s: float = 0.0

    @classmethod
    def parse(cls, options: dict[str, str]) -> NodeOptions:
        known = {f.name for f in fields(cls)}
        values: dict[str, float] = {}
        for key, text in options.items():
            if key not in known:
                raise ValueError(f"unknown option {key!r}; options: {', '.join(sorted(known))}")
            try:
                value = float(text)
            except ValueError:
                raise ValueError(f"option {key}: {text!r} is not a number") from None
            if not value >= 0.0 or value == float("inf"):
                raise ValueError(f"option {key}: must be a finite number >= 0, got {text!r}")
            values[key] = value
        return cls(**values)


def build_autopilot(scenario: Scenario, vehicle_id: str, options: NodeOptions) -> Autopilot:
    index = [v.id for v in scenario.vehicles].index(vehicle_id)
    seed = scenario.world.seed
    estimator = Estimator(
        options.position_noise_m,
        options.velocity_noise_m_s,
        np.random.SeedSequence([seed, index, 0xE57]),
    )
    spec = scenario.vehicle(vehicle_id).behavior
    behavior = None
    if spec is not None:
        ctx = BehaviorContext(
            vehicle_id=vehicle_id,
            vehicle_index=index,
            scenario=scenario,
            control_dt_s=1.0 / scenario.time.control_hz,
            rng=np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, index, 0xBE4]))),
        )
        behavior = load_behavior(spec, ctx)
    return Autopilot(scenario, vehicle_id, estimator=estimator, behavior=behavior)


class _Served:
    """One served vehicle: its autopilot, sensor and publishers."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        scenario: Scenario,
        vehicle_id: str,
        options: NodeOptions,
        wind: WindModel,
        own_actuators: bool = True,
    ) -> None:
        self.vehicle_id = vehicle_id
        self.autopilot = build_autopilot(scenario, vehicle_id, options)
        index = [v.id for v in scenario.vehicles].index(vehicle_id)
        self.sensor = ConcentrationSensor(scenario.sensor, scenario.world.seed, index)
        self.anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, index)
        self.wind_pub = (
            session.declare_publisher(keys.vehicle_wind(vehicle_id))
            if scenario.anemometer.period_ticks > 0
            else None
        )
        # None: the process batches its vehicles' commands (AutopilotNode.batch_pub)
        self.actuators = (
            session.declare_publisher(keys.vehicle_actuators(vehicle_id)) if own_actuators else None
        )
        self.status_pub = session.declare_publisher(keys.vehicle_status(vehicle_id))
        self.readings_pub = session.declare_publisher(keys.vehicle_concentration(vehicle_id))
        self.last_command = b""
        self.last_status: VehicleStatus | None = None
        self.last_status_time_s = -1e9
        self.new_readings: list[ConcentrationReading] = []

    def publish_status(self, force: bool, period_s: float) -> None:
        status = self.autopilot.status()
        last = self.last_status
        changed = last is None or _status_key(last) != _status_key(status)
        if force or changed or status.sim_time_s - self.last_status_time_s >= period_s:
            self.status_pub.put(encode(status))
            self.last_status = status
            self.last_status_time_s = status.sim_time_s


def _status_key(s: VehicleStatus) -> tuple[object, ...]:
    return (
        s.mode,
        s.armed,
        s.landed,
        s.crashed,
        s.mission_index,
        s.mission_count,
        s.mission_items_reached,
        s.mission_finished,
        s.failsafe,
        s.health,
    )


class _TickView(msgspec.Struct, frozen=True, tag_field="schema", tag=SimTick.__struct_config__.tag):
    """A ``SimTick`` whose states stay undecoded: an autopilot fully decodes only its own."""

    tick: int
    sim_time_s: float
    states: list[msgspec.Raw]
    plume_queried: bool = False
    plume_values: PlumeSample | None = None


class _StateHead(
    msgspec.Struct, frozen=True, tag_field="schema", tag=VehicleState.__struct_config__.tag
):
    """What an autopilot needs of every state in a tick: who and where (the sensor query)."""

    vehicle_id: str
    position_enu_m: tuple[float, float, float]


_head_decoder = msgspec.msgpack.Decoder(_StateHead)


@dataclass
class _Tick:
    """One decoded tick: number, time, who is where, and the raw states."""

    tick: int
    sim_time_s: float
    heads: list[_StateHead]
    raw: list[msgspec.Raw]
    plume_queried: bool = False
    plume_values: PlumeSample | None = None

    @classmethod
    def decode(cls, data: bytes) -> _Tick:
        view = decode(data, _TickView)
        try:
            heads = [_head_decoder.decode(r) for r in view.states]
        except (msgspec.ValidationError, msgspec.DecodeError) as exc:
            raise MessageError("SimTick", "states", str(exc)) from None
        return cls(
            view.tick, view.sim_time_s, heads, view.states, view.plume_queried, view.plume_values
        )

    @classmethod
    def of(cls, tick: SimTick) -> _Tick:
        raw = [msgspec.Raw(encode(s)) for s in tick.states]
        heads = [_StateHead(s.vehicle_id, s.position_enu_m) for s in tick.states]
        return cls(tick.tick, tick.sim_time_s, heads, raw, tick.plume_queried, tick.plume_values)


@dataclass
class _PendingSensor:
    tick: int
    sim_time_s: float
    states: list[_StateHead]
    replies: zenoh.handlers.Handler[zenoh.Reply] | None  # None: no plume node was alive
    by_physics: bool = False  # the physics queried: the answer comes with the next tick


class AutopilotNode:
    """The loop of one autopilot process (bus glue around :class:`Autopilot`)."""

    def __init__(self, session: zenoh.Session, ctx: NodeContext, options: NodeOptions) -> None:
        self.session = session
        self.keys = ctx.keys
        self.options = options
        self.lock = threading.Lock()
        batched = len(ctx.vehicle_ids) > 1
        wind = wind_from_scenario(ctx.scenario)  # one wind for every vehicle served here
        self.served = {
            vid: _Served(session, self.keys, ctx.scenario, vid, options, wind, not batched)
            for vid in ctx.vehicle_ids
        }
        self.batch_pub = (
            session.declare_publisher(self.keys.autopilot_actuators(ctx.name)) if batched else None
        )
        self.last_batch = b""
        self.last_tick = -1
        self.last_tick_wall = 0.0
        self.control_dt_s = 1.0 / ctx.scenario.time.control_hz
        self._slot_lock = threading.Lock()  # guards _latest and _draining
        self._latest: zenoh.Sample | None = None  # the newest tick not handled yet
        self._draining = False  # a thread is handling ticks
        self._handoff = threading.Event()  # the worker thread takes over the draining
        self._stop = threading.Event()
        self.pending: _PendingSensor | None = None
        self.plume_key = self.keys.plume_concentration()
        self.sensor_timeout_s = options.sensor_timeout_s or (
            0.4 * ctx.scenario.time.participant_timeout_s
        )
        # Queries go out only while a plume node is alive: a dead service is reported as
        # unavailable at once instead of costing every tick the full timeout.
        self.plume_nodes: set[str] = set()
        self._declared: list[Any] = []  # subscribers and queryables, undeclared on close
        self._tokens: list[zenoh.LivelinessToken] = []

    # ------------------------------------------------------------------ set-up
    def declare(self, node_name: str) -> None:
        """Subscriber and queryables first, then the participants' tokens."""
        self._declared.append(
            self.session.liveliness().declare_subscriber(
                self.keys.all_node_health(), self._on_presence, history=True
            )
        )
        # A callback subscriber (zenoh-python runs it on its callback thread, not on a Zenoh
        # runtime thread): see _on_tick_sample for order, exclusion and the blocking case.
        self._declared.append(
            self.session.declare_subscriber(self.keys.tick(), self._on_tick_sample)
        )
        for vid, served in self.served.items():
            self._declared.append(
                self.session.declare_queryable(
                    self.keys.vehicle_cmd(vid), self._command_handler(served)
                )
            )
        for vid in self.served:
            name = f"autopilot-{vid}"
            if name != node_name:
                self._tokens.append(
                    self.session.liveliness().declare_token(self.keys.node_health(name))
                )
        for served in self.served.values():
            served.publish_status(force=True, period_s=self.options.status_period_s)

    def _on_presence(self, sample: zenoh.Sample) -> None:
        try:
            name = self.keys.node_name_of(str(sample.key_expr))
        except ValueError:
            return
        if name == "plume" or name.startswith("plume-"):
            if sample.kind == zenoh.SampleKind.PUT:
                self.plume_nodes.add(name)
            else:
                self.plume_nodes.discard(name)

    def close(self) -> None:
        for token in self._tokens:
            with suppress(zenoh.ZError):
                token.undeclare()
        for entity in self._declared:
            with suppress(zenoh.ZError):
                entity.undeclare()

    def _command_handler(self, served: _Served) -> Callable[[zenoh.Query], None]:
        def handle(query: zenoh.Query) -> None:
            try:
                payload = query.payload
                data = payload.to_bytes() if payload is not None else b""
                command: object = decode(data, Command)  # type: ignore[arg-type]
            except MessageError as exc:
                log.warning("%s: bad command: %s", served.vehicle_id, exc)
                query.reply_err(encode(ErrorReply(field=exc.field, reason=exc.reason[:1000])))
                return
            try:
                with self.lock:
                    reply = served.autopilot.handle(command)
                    served.publish_status(force=False, period_s=self.options.status_period_s)
                if not reply.accepted:
                    log.info(
                        "%s: %s refused: %s",
                        served.vehicle_id,
                        type(command).__name__,
                        reply.reason,
                    )
                query.reply(query.key_expr, encode(reply))
            except Exception:  # the process must outlive any one command
                log.exception("%s: command handling failed", served.vehicle_id)

        return handle

    # ------------------------------------------------------------------ loop
    def run(self, stop: threading.Event) -> None:
        """Ticks run in the subscriber's callback (and on a worker for the rare blocking case);
        the main thread keeps statuses flowing while none arrive."""
        self._stop = stop
        worker = threading.Thread(
            target=self._blocking_ticks, args=(stop,), name="ticks", daemon=True
        )
        worker.start()
        while not stop.wait(IDLE_STATUS_PERIOD_S):
            with self.lock:
                if time.monotonic() - self.last_tick_wall >= IDLE_STATUS_PERIOD_S:
                    for served in self.served.values():
                        served.publish_status(force=True, period_s=0.0)
        self._handoff.set()  # wake the worker to end

    def _on_tick_sample(self, sample: zenoh.Sample) -> None:
        """The tick subscriber's callback (zenoh-python's callback thread; written to be safe on
        any number of Zenoh rx threads too, should the callback be made direct).

        One thread at a time drains ticks: a sample that arrives while another thread drains is
        left in the slot and the draining thread takes it next; a newer sample replaces an
        unhandled one (behind: only the latest counts), so ticks stay in arrival order and never
        run concurrently. A tick that would wait for this autopilot's own plume query (the
        physics did not query) is not handled here — blocking a callback thread could hold up the
        reply it waits for, and other callbacks — but handed to the worker thread, which drains
        until no tick is left.
        """
        with self._slot_lock:
            self._latest = sample
            if self._draining:
                return
            self._draining = True
        self._drain(may_block=False)

    def _drain(self, may_block: bool) -> None:
        while True:
            with self._slot_lock:
                sample = self._latest
                if sample is None or self._stop.is_set():
                    self._draining = False
                    return
                if not may_block and self.pending is not None and self.pending.replies is not None:
                    self._handoff.set()  # the worker drains on (the flag stays set for it)
                    return
                self._latest = None
            self._handle_sample(sample)

    def _blocking_ticks(self, stop: threading.Event) -> None:
        while not stop.is_set():
            self._handoff.wait()
            self._handoff.clear()
            if stop.is_set():
                return
            self._drain(may_block=True)

    def _handle_sample(self, sample: zenoh.Sample) -> None:
        try:
            tick = _Tick.decode(sample.payload.to_bytes())
        except MessageError as exc:
            log.warning("ignoring bad tick: %s", exc)
            return
        try:
            self.on_tick(tick)
        except Exception:  # never let one tick end the ticks; physics would drop us
            if not self._stop.is_set():
                log.exception("tick %d failed", tick.tick)

    def on_tick(self, tick: SimTick | _Tick) -> None:
        if isinstance(tick, SimTick):
            tick = _Tick.of(tick)
        self.last_tick_wall = time.monotonic()
        if tick.tick == self.last_tick:  # the start handshake repeats a tick: same answer
            if self.batch_pub is not None and self.last_batch:
                self.batch_pub.put(self.last_batch)
            for served in self.served.values():
                if served.actuators is not None and served.last_command:
                    served.actuators.put(served.last_command)
            return
        if tick.tick < self.last_tick:
            # Physics restarted from a checkpoint: fly on from its tick (timers stretch by it).
            log.warning(
                "sim time went back from tick %d to %d (t=%.3f s): physics resumed from a "
                "checkpoint, replaying %.3f s",
                self.last_tick,
                tick.tick,
                tick.sim_time_s,
                (self.last_tick - tick.tick) * self.control_dt_s,
            )
            self.pending = None  # the sensor query of a tick that is being replayed
        self.last_tick = tick.tick
        self._collect_readings(tick)
        index = {h.vehicle_id: k for k, h in enumerate(tick.heads)}
        batch: list[ActuatorCommand] = []
        with self.lock:
            for vid, served in self.served.items():
                own = index.get(vid)
                if own is None:
                    continue
                try:
                    state = decode(tick.raw[own], VehicleState)
                    # Only a behaviour looks at the peers: decode them for it alone.
                    peers = (
                        [decode(r, VehicleState) for k, r in enumerate(tick.raw) if k != own]
                        if served.autopilot.behavior is not None
                        else []
                    )
                except MessageError as exc:
                    log.warning("%s: ignoring bad state in tick %d: %s", vid, tick.tick, exc)
                    continue
                if served.wind_pub is not None and served.anemometer.due(tick.tick):
                    wind = served.anemometer.read(
                        vid, tick.tick, tick.sim_time_s, state.position_enu_m
                    )
                    served.wind_pub.put(encode(wind))
                rotor = served.autopilot.step(state, peers, served.new_readings)
                served.new_readings = []
                command = ActuatorCommand(vehicle_id=vid, tick=tick.tick, rotor_commands=rotor)
                if served.actuators is None:
                    batch.append(command)
                else:
                    served.last_command = encode(command)
                    served.actuators.put(served.last_command)
                for event in served.autopilot.modes.mission.drain_events():
                    log.info(
                        "%s: mission item %d reached at %.2f s", vid, event.index, event.sim_time_s
                    )
            if self.batch_pub is not None and batch:
                self.last_batch = encode(ActuatorBatch(tick=tick.tick, commands=batch))
                self.batch_pub.put(self.last_batch)
            for served in self.served.values():
                served.publish_status(force=False, period_s=self.options.status_period_s)
        if any(s.sensor.due(tick.tick) for s in self.served.values()) and tick.heads:
            if tick.plume_queried:
                self.pending = _PendingSensor(tick.tick, tick.sim_time_s, tick.heads, None, True)
            else:
                self._query_plume(tick)

    # ------------------------------------------------------------------ sensor
    def _ask_plume(self, pending: _PendingSensor) -> _PendingSensor:
        """``pending`` with this autopilot's own query for its positions (no plume: none)."""
        if not self.plume_nodes:
            return _PendingSensor(pending.tick, pending.sim_time_s, pending.states, None)
        query = PlumeQuery(
            points_enu_m=[s.position_enu_m for s in pending.states],
            sim_time_s=pending.sim_time_s,
        )
        replies = self.session.get(
            self.plume_key, payload=encode(query), timeout=self.sensor_timeout_s
        )
        return _PendingSensor(pending.tick, pending.sim_time_s, pending.states, replies)

    def _query_plume(self, tick: _Tick) -> None:
        self.pending = self._ask_plume(_PendingSensor(tick.tick, tick.sim_time_s, tick.heads, None))

    def _collect_readings(self, tick: _Tick) -> None:
        pending = self.pending
        if pending is None:
            return
        answer = tick.plume_values
        if pending.by_physics and (answer is None or answer.tick != pending.tick):
            return  # not the tick with the physics' answer (e.g. garbage on sim/tick): wait
        self.pending = None
        values = self._values(pending, tick.plume_values)
        index: dict[str, int] = {}
        for k, s in enumerate(pending.states):
            index.setdefault(s.vehicle_id, k)
        # Every vehicle's PeerReading, built once per tick and shared by the served vehicles'
        # readings (frozen): K x N constructions per tick would be N.
        everyone: list[PeerReading] | None = None
        for vid, served in self.served.items():
            if not served.sensor.due(pending.tick):
                continue
            own = index.get(vid)
            if own is None:
                continue
            position = pending.states[own].position_enu_m
            true = values[own] if values is not None else None
            peers: list[PeerReading] = []
            if values is not None:
                if everyone is None:
                    everyone = [
                        PeerReading(
                            vehicle_id=s.vehicle_id,
                            position_enu_m=s.position_enu_m,
                            true_g_m3=values[k],
                        )
                        for k, s in enumerate(pending.states)
                    ]
                peers = everyone[:own] + everyone[own + 1 :]
            reading = served.sensor.reading(vid, pending.sim_time_s, position, true, peers)
            served.autopilot.sensor_health = (
                "" if reading.available else "sensor: the plume service did not answer"
            )
            served.readings_pub.put(encode(reading))
            served.new_readings.append(reading)

    def _values(
        self, pending: _PendingSensor, from_physics: PlumeSample | None
    ) -> list[float] | None:
        """The plume's values for the pending query, or None (no answer in time, or an error)."""
        if pending.by_physics:
            if from_physics is None or from_physics.tick != pending.tick:
                return None  # not reached: _collect_readings waits for the answering tick
            values = from_physics.values_g_m3
            if values is not None and len(values) != len(pending.states):
                log.warning(
                    "physics sent %d values for %d points", len(values), len(pending.states)
                )
                return None
            return values
        if pending.replies is None:
            return None
        try:
            for reply in pending.replies:
                if reply.ok is None:
                    err = reply.err
                    log.warning("plume query refused: %s", err.payload.to_bytes() if err else "")
                    return None
                values = decode(reply.ok.payload.to_bytes(), PlumeValues).values_g_m3
                if len(values) != len(pending.states):
                    log.warning(
                        "plume answered %d values for %d points", len(values), len(pending.states)
                    )
                    return None
                return values
        except (MessageError, zenoh.ZError) as exc:
            log.warning("plume reply unusable: %s", exc)
        return None


def main(ctx: NodeContext) -> int:
    """Serve ``ctx.vehicle_ids`` until stopped."""
    if not ctx.vehicle_ids:
        log.error("autopilot: no vehicle to serve (--vehicle ID)")
        return 2
    try:
        options = NodeOptions.parse(ctx.options)
        for vid in ctx.vehicle_ids:  # fail fast on a bad behaviour before joining the bus
            ctx.scenario.vehicle(vid)
    except (ValueError, KeyError) as exc:
        log.error("autopilot: %s", exc)
        return 2
    # Before the session opens (Zenoh reads it once, when its runtime starts); an operator's
    # own ZENOH_RUNTIME wins.
    os.environ.setdefault("ZENOH_RUNTIME", ZENOH_RUNTIME)
    with NodeRuntime(ctx, role="autopilot") as rt:
        try:
            node = AutopilotNode(rt.session, ctx, options)
        except BehaviorError as exc:
            log.error("autopilot: %s", exc)
            return 2
        node.declare(ctx.name)
        rt.ready()
        try:
            node.run(rt.stop)
        finally:
            node.close()
    return 0
