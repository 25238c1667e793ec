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
``status_period_s`` (0.5; a stepped world gets a status every tick), ``position_noise_m`` /
``velocity_noise_m_s`` (0: the estimate is the physics' truth), ``checkpoint`` (a file path;
empty: none): keep snapshots of the process's state there, so a restarted process, or a physics
resumed from its checkpoint, carries on with the same bits (:mod:`agents.resume`). Plume
queries go out only while a ``plume`` node's token is alive.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import msgspec
import numpy as np
import zenoh

from agents.anemometer import Anemometer
from agents.autopilot import Autopilot
from agents.behavior import BehaviorContext, BehaviorError, load_behavior
from agents.estimator import Estimator
from agents.flight import Flight, take_readings
from agents.resume import StateKeeper
from agents.sensor import ConcentrationSensor
from agents.snapshot import PendingSnapshot, ProcessSnapshot, SnapshotError, capture, restore
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Command,
    CommandReply,
    PlumeQuery,
    PlumeSample,
    PlumeValues,
    SimTick,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, RoleOptions, parse_options
from swarmbus.reqrep import Pending, RequestError, ask, serve
from swarmbus.scenario import Scenario
from swarmbus.session import SINGLE_THREAD_RUNTIME
from swarmbus.views import StateHead, TickView, state_head_decoder
from swarmbus.wind import WindModel, wind_from_scenario

log = logging.getLogger(__name__)

IDLE_STATUS_PERIOD_S = 1.0  # wall clock: status while no ticks arrive (physics not running)


NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]


class NodeOptions(RoleOptions, frozen=True, kw_only=True):
    """The autopilot role's options (``--set KEY=VALUE``)."""

    # 0: derived from the scenario, 0.4 × participant_timeout_s (so a slow answer on a loaded
    # machine is still waited for, and the lockstep never drops us for waiting).
    sensor_timeout_s: NonNegative = 0.0
    status_period_s: NonNegative = 0.5
    position_noise_m: NonNegative = 0.0
    velocity_noise_m_s: NonNegative = 0.0
    checkpoint: str = ""  # snapshots of the process's state (agents.resume); empty: none


def behavior_rng(scenario: Scenario, vehicle_id: str) -> np.random.Generator:
    """The generator a vehicle's behaviour gets in its context."""
    index = [v.id for v in scenario.vehicles].index(vehicle_id)
    seed = scenario.world.seed
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, index, 0xBE4])))


def build_autopilot(
    scenario: Scenario,
    vehicle_id: str,
    options: NodeOptions,
    rng: np.random.Generator | None = None,
) -> Autopilot:
    """``rng``: the behaviour's generator (default: :func:`behavior_rng`)."""
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
            rng=rng if rng is not None else behavior_rng(scenario, vehicle_id),
        )
        behavior = load_behavior(spec, ctx)
    return Autopilot(scenario, vehicle_id, estimator=estimator, behavior=behavior)


def build_flight(
    scenario: Scenario,
    vehicle_id: str,
    options: NodeOptions,
    rng: np.random.Generator | None = None,
) -> Flight:
    """A vehicle's autopilot and sensor, seeded from the scenario and the vehicle's index
    (``rng``: the behaviour's generator, default :func:`behavior_rng`)."""
    index = [v.id for v in scenario.vehicles].index(vehicle_id)
    sensor = ConcentrationSensor.for_vehicle(scenario, index)
    return Flight(build_autopilot(scenario, vehicle_id, options, rng), sensor)


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
        self.behavior_rng = behavior_rng(scenario, vehicle_id)
        self.flight = build_flight(scenario, vehicle_id, options, self.behavior_rng)
        self.autopilot = self.flight.autopilot
        self.sensor = self.flight.sensor
        index = [v.id for v in scenario.vehicles].index(vehicle_id)
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


@dataclass
class _Tick:
    """One decoded tick: number, time, who is where, and the raw states."""

    tick: int
    sim_time_s: float
    heads: list[StateHead]
    raw: list[msgspec.Raw]
    plume_queried: bool = False
    plume_values: PlumeSample | None = None

    @classmethod
    def decode(cls, data: bytes) -> _Tick:
        view = decode(data, TickView)
        try:
            heads = [state_head_decoder.decode(r) for r in view.states]
        except (msgspec.ValidationError, msgspec.DecodeError) as exc:
            raise MessageError("SimTick", "states", str(exc)) from None
        return cls(
            view.tick, view.sim_time_s, heads, view.states, view.plume_queried, view.plume_values
        )

    @classmethod
    def of(cls, tick: SimTick) -> _Tick:
        raw = [msgspec.Raw(encode(s)) for s in tick.states]
        heads = [StateHead(s.vehicle_id, s.position_enu_m) for s in tick.states]
        return cls(tick.tick, tick.sim_time_s, heads, raw, tick.plume_queried, tick.plume_values)


@dataclass
class _PendingSensor:
    tick: int
    sim_time_s: float
    states: list[StateHead]
    replies: Pending[PlumeValues] | None  # None: no plume node was alive
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
        # A stepped world's client decides between steps on what it has seen: a status every
        # tick lets it know it has seen the tick it paused at (agents.Swarm waits for that).
        stepped = ctx.scenario.time.mode == "stepped"
        self.status_period_s = 0.0 if stepped else options.status_period_s
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
        # Snapshots (agents.resume): the keeper, and the tick part of the latest snapshot.
        self.keeper: StateKeeper | None = None
        if options.checkpoint:
            period = ctx.scenario.time.checkpoint_period_s * ctx.scenario.time.control_hz
            self.keeper = StateKeeper(Path(options.checkpoint), round(period))
        self._snap_pending: PendingSnapshot | None = None
        self._snap_tick = -1  # the tick of the state under the lock (last_tick runs ahead)
        self.node_name = ctx.name

    # ------------------------------------------------------------------ set-up
    def declare(self, node_name: str) -> None:
        """Subscriber and queryables first, then the participants' tokens."""
        if self.keeper is not None:
            self.keeper.open(self._snapshot())
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
            key, handler = self.keys.vehicle_cmd(vid), self._command_handler(served)
            commands = serve(self.session, key, Command, handler)  # type: ignore[arg-type]
            self._declared.append(commands)
        for vid in self.served:
            name = autopilot_node(vid)
            if name != node_name:
                self._tokens.append(
                    self.session.liveliness().declare_token(self.keys.node_health(name))
                )
        for served in self.served.values():
            served.publish_status(force=True, period_s=self.status_period_s)

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
        if self.keeper is not None:
            self.keeper.close()
        for token in self._tokens:
            with suppress(zenoh.ZError):
                token.undeclare()
        for entity in self._declared:
            with suppress(zenoh.ZError):
                entity.undeclare()

    def _command_handler(self, served: _Served) -> Callable[[Command], CommandReply]:
        def handle(command: Command) -> CommandReply:
            with self.lock:
                reply = served.autopilot.handle(command)
                served.publish_status(force=False, period_s=self.status_period_s)
                self._save()
            if not reply.accepted:
                log.info(
                    "%s: %s refused: %s", served.vehicle_id, type(command).__name__, reply.reason
                )
            return reply

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
        if self.keeper is not None:
            self._resume(tick)
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
        if self.keeper is not None:
            self.keeper.before_tick(tick.tick)
        self._collect_readings(tick)
        index = {h.vehicle_id: k for k, h in enumerate(tick.heads)}
        batch: list[ActuatorCommand] = []
        sensing = any(s.sensor.due(tick.tick) for s in self.served.values()) and bool(tick.heads)
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
                rotor = served.flight.step(state, peers)
                command = ActuatorCommand(vehicle_id=vid, tick=tick.tick, rotor_commands=rotor)
                if served.actuators is None:
                    batch.append(command)
                else:
                    served.last_command = encode(command)
                for event in served.autopilot.modes.mission.drain_events():
                    log.info(
                        "%s: mission item %d reached at %.2f s", vid, event.index, event.sim_time_s
                    )
            if self.batch_pub is not None and batch:
                self.last_batch = encode(ActuatorBatch(tick=tick.tick, commands=batch))
            self._snap_tick = tick.tick
            if self.keeper is not None:  # saved before the answer goes out (agents.resume)
                self._snap_pending = self._pending_after(tick, sensing)
                self._save()
            if self.batch_pub is not None and batch:
                self.batch_pub.put(self.last_batch)
            for served in self.served.values():
                if served.actuators is not None and served.last_command:
                    served.actuators.put(served.last_command)
            for served in self.served.values():
                served.publish_status(force=False, period_s=self.status_period_s)
        if sensing:
            if tick.plume_queried:
                self.pending = _PendingSensor(tick.tick, tick.sim_time_s, tick.heads, None, True)
            else:
                self._query_plume(tick)

    # ------------------------------------------------------------------ snapshots
    def _pending_after(self, tick: _Tick, sensing: bool) -> PendingSnapshot | None:
        """The sensor query in flight once ``tick`` is handled (see on_tick's end)."""
        p = self.pending
        if sensing:
            heads, sim_time, tick_no, by_physics = (
                tick.heads,
                tick.sim_time_s,
                tick.tick,
                tick.plume_queried,
            )
        elif p is not None:
            heads, sim_time, tick_no, by_physics = p.states, p.sim_time_s, p.tick, p.by_physics
        else:
            return None
        return PendingSnapshot(
            tick=tick_no,
            sim_time_s=sim_time,
            heads=[(h.vehicle_id, h.position_enu_m) for h in heads],
            by_physics=by_physics,
        )

    def _snapshot(self) -> bytes:
        """The process's state now (caller holds the lock, or no tick has run yet)."""
        served = list(self.served.values())
        snap = ProcessSnapshot(
            node=self.node_name,
            tick=self._snap_tick,
            vehicles=[capture(s.autopilot, s.sensor, s.behavior_rng) for s in served],
            commands=[s.last_command for s in served],
            batch=self.last_batch,
            status_times_s=[s.last_status_time_s for s in served],
            pending=self._snap_pending,
        )
        return msgspec.msgpack.encode(snap)

    def _save(self) -> None:
        keeper = self.keeper
        if keeper is None:
            return
        try:
            keeper.save(self._snapshot())
        except (SnapshotError, OSError) as exc:
            log.error("snapshots off: %s", exc)
            self.keeper = None
        except Exception:  # a snapshot must never cost the vehicle its ticks
            log.exception("snapshots off: a snapshot failed")
            self.keeper = None

    def _resume(self, tick: _Tick) -> None:
        """Restore a snapshot when this tick calls for one (agents.resume)."""
        keeper = self.keeper
        assert keeper is not None
        if self.last_tick < 0:
            snap = keeper.for_restart(tick.tick)
            how = "restarted process"
        elif tick.tick < self.last_tick:
            snap = keeper.for_rewind(tick.tick)
            how = "physics resumed from its checkpoint"
        else:
            return
        if snap is None:
            return
        with self.lock:
            self._restore(snap)
        log.warning(
            "%s: restored the state of tick %d for tick %d (%s)",
            ", ".join(self.served),
            snap.tick,
            tick.tick,
            how,
        )

    def _restore(self, snap: ProcessSnapshot) -> None:
        served = list(self.served.values())
        if [v.vehicle_id for v in snap.vehicles] != list(self.served):
            log.error("snapshot of %s, not of this process's vehicles: not restored", snap.node)
            return
        for s, v, cmd, when in zip(
            served, snap.vehicles, snap.commands, snap.status_times_s, strict=True
        ):
            restore(s.autopilot, s.sensor, v, s.behavior_rng)
            s.last_command = cmd
            s.last_status_time_s = when
            s.flight.new_readings = []
        self.last_batch = snap.batch
        self.last_tick = self._snap_tick = snap.tick
        self._snap_pending = p = snap.pending
        self.pending = None
        if p is not None:
            heads = [StateHead(vid, pos) for vid, pos in p.heads]
            pending = _PendingSensor(p.tick, p.sim_time_s, heads, None, p.by_physics)
            self.pending = pending if p.by_physics else self._ask_plume(pending)
        if self.keeper is not None:
            self.keeper.save(msgspec.msgpack.encode(snap))

    # ------------------------------------------------------------------ sensor
    def _ask_plume(self, pending: _PendingSensor) -> _PendingSensor:
        """``pending`` with this autopilot's own query for its positions (no plume: none)."""
        if not self.plume_nodes:
            return _PendingSensor(pending.tick, pending.sim_time_s, pending.states, None)
        query = PlumeQuery(
            points_enu_m=[s.position_enu_m for s in pending.states],
            sim_time_s=pending.sim_time_s,
        )
        replies = ask(self.session, self.plume_key, query, PlumeValues, self.sensor_timeout_s)
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
        flights = [served.flight for served in self.served.values()]
        taken = take_readings(flights, pending.tick, pending.sim_time_s, pending.states, values)
        for flight, reading in taken:
            self.served[flight.vehicle_id].readings_pub.put(encode(reading))

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
        outcome = pending.replies.outcome()
        if isinstance(outcome, RequestError):
            if pending.replies.answered:  # (no answer at all: no plume service any more)
                log.warning("plume query: %s", outcome)
            return None
        values = outcome.values_g_m3
        if len(values) != len(pending.states):
            log.warning("plume answered %d values for %d points", len(values), len(pending.states))
            return None
        return values


def main(ctx: NodeContext) -> int:
    """Serve ``ctx.vehicle_ids`` until stopped."""
    if not ctx.vehicle_ids:
        log.error("autopilot: no vehicle to serve (--vehicle ID)")
        return 2
    try:
        options = parse_options(NodeOptions, ctx.options)
        for vid in ctx.vehicle_ids:  # fail fast on a bad behaviour before joining the bus
            ctx.scenario.vehicle(vid)
    except (OptionError, KeyError) as exc:
        log.error("autopilot: %s", exc)
        return 2
    # Before the session opens (Zenoh reads it once, when its runtime starts); an operator's
    # own ZENOH_RUNTIME wins.
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)
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
