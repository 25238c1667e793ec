"""The autopilot process (``plumeswarm node autopilot --vehicle ID [--vehicle ID2 …]``): one
loop over typed events serving one vehicle or K of them; options in
:class:`agents.build.AutopilotOptions`. See docs/agents.md and docs/architecture.md ("How a
tick flows").
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from contextlib import suppress
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from agents.anemometer import Anemometer
from agents.behavior import BehaviorError, talks
from agents.build import AutopilotOptions, build_flight, vehicle_index
from agents.checkpoint import (
    CheckpointError,
    HandledCommand,
    PendingCheckpoint,
    ProcessCheckpoint,
    capture,
    restore,
)
from agents.flight import Flight, take_readings
from agents.node_events import Idle, Inbox, PendingSensor, Tick, TickArrived
from agents.peer_link import Mailbox, PeerLink, RadioError
from agents.resume import StateKeeper
from agents.sensor import ConcentrationSensor
from plume_atmosphere.wind import WindModel, wind_from_scenario
from swarmbus.catchup import CatchUpPublisher, Resender, RouterOutage, watch_router
from swarmbus.codec import MessageError, decode, encode, refusals
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Command,
    CommandReply,
    ConcentrationReading,
    PlumeSample,
    RadioBatch,
    SimTick,
    VehicleState,
    VehicleStatus,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, role_options
from swarmbus.reqrep import Incoming, serve_later
from swarmbus.scenario import Scenario
from swarmbus.session import SINGLE_THREAD_RUNTIME, payload_or_none
from swarmbus.views import StateHead

log = logging.getLogger(__name__)

IDLE_STATUS_PERIOD_S = 1.0  # wall clock: status while no ticks arrive (physics not running)
# The readings kept per vehicle, put again for a subscriber back after a router outage
# (swarmbus.catchup): 25.6 s of sim time at the default 10 Hz sensor.
READINGS_KEPT = 256
# A talking behaviour's last radio batches, answered to a receiver that missed some (one
# restarted, or that joined late).
RADIO_KEPT = 64
RADIO_QUERY_TIMEOUT_S = 1.0
RADIO_ASK_AFTER_S = 0.1  # a held tick's missing batches are asked of their senders after this


class _Served:
    """One served vehicle: its autopilot, sensor and publishers."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        scenario: Scenario,
        vehicle_id: str,
        options: AutopilotOptions,
        wind: WindModel,
        resender: Resender,
        mailbox: Mailbox,
    ) -> None:
        self.vehicle_id = vehicle_id
        # Where the physics puts this vehicle's state in a tick (checked on every use).
        self.index = vehicle_index(scenario, vehicle_id)
        self.flight = build_flight(scenario, vehicle_id, options, mailbox)
        self.autopilot = self.flight.autopilot
        self.sensor = self.flight.sensor
        self.anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, self.index)
        self.wind_pub = (
            session.declare_publisher(keys.vehicle_wind(vehicle_id))
            if scenario.anemometer.period_ticks > 0
            else None
        )
        self.status_pub = session.declare_publisher(keys.vehicle_status(vehicle_id))
        # a realtime tick may wait this long for a slow participant: no tick then is no loss
        self.state_loss_s = max(
            scenario.failsafe_for(vehicle_id).state_loss_timeout_s,
            scenario.time.participant_timeout_s,
        )
        self.readings_pub = CatchUpPublisher(
            session, keys.vehicle_concentration(vehicle_id), READINGS_KEPT, resender
        )
        self.last_status: VehicleStatus | None = None
        self.last_status_time_s = -1e9
        self.link: PeerLink | None = None  # the radio (set when it is not a plain hand-over)

    def publish_status(self, force: bool, period_s: float) -> None:
        status = self.autopilot.status()
        if self.link is not None:
            status = msgspec.structs.replace(status, radio=self.link.link_status(self.vehicle_id))
        last = self.last_status
        changed = last is None or _status_key(last) != _status_key(status)
        if force or changed or status.sim_time_s - self.last_status_time_s >= period_s:
            self.status_pub.put(encode(status))
            self.last_status = status
            self.last_status_time_s = status.sim_time_s

    def step(
        self, tick: Tick, heard: dict[str, list[VehicleState]] | None
    ) -> ActuatorCommand | None:
        """This vehicle's answer to ``tick`` (None: its state is not in the tick, or is bad);
        ``heard``: each vehicle's peers as the radio brought them (None: every peer's state
        of the tick)."""
        vid = self.vehicle_id
        try:
            found = tick.state_of(vid, self.index)
            if found is None:
                return None
            own, state = found
            # Only a behaviour looks at the peers: decode them for it alone.
            peers: list[VehicleState] = []
            if self.autopilot.behavior is not None:
                peers = tick.peers_of(own) if heard is None else heard.get(vid, [])
        except MessageError as exc:
            log.warning("%s: ignoring bad state in tick %d: %s", vid, tick.tick, exc)
            return None
        if self.wind_pub is not None and self.anemometer.due(tick.tick):
            wind = self.anemometer.read(vid, tick.tick, tick.sim_time_s, state.position_enu_m)
            self.wind_pub.put(encode(wind))
        rotor = self.flight.step(state, peers)
        for event in self.autopilot.modes.mission.drain_events():
            log.info("%s: mission item %d reached at %.2f s", vid, event.index, event.sim_time_s)
        return ActuatorCommand(vehicle_id=vid, tick=tick.tick, rotor_commands=rotor)


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


@dataclass(frozen=True, slots=True)
class CommandArrived:
    """A decoded command for one served vehicle, to answer from the loop."""

    served: _Served
    incoming: Incoming[Command]


@dataclass(frozen=True, slots=True)
class RadioArrived:
    """A ``RadioBatch`` of another process's vehicle (still encoded)."""

    data: bytes


Event = TickArrived | CommandArrived | RadioArrived


class AutopilotNode:
    """One autopilot process: one loop over its events (:meth:`run`)."""

    def __init__(self, session: zenoh.Session, ctx: NodeContext, options: AutopilotOptions) -> None:
        self.session = session
        self.keys = ctx.keys
        self.options = options
        self.inbox: Inbox[Event] = Inbox()
        wind = wind_from_scenario(ctx.scenario)  # one wind for every vehicle served here
        # the readings put again after a router outage, off the loop's thread
        self.resender = Resender("autopilot-catch-up")
        # The radio: the same decisions as in every other process and runner (the whole
        # swarm's link, fed with every vehicle's state, sample and message).
        scenario = ctx.scenario
        self.link = PeerLink(scenario)
        boxes = self.link.mailboxes
        self.served = {
            vid: _Served(
                session, self.keys, scenario, vid, options, wind, self.resender, boxes[vid]
            )
            for vid in ctx.vehicle_ids
        }
        self.talkers = [
            v.id for v in scenario.vehicles if v.behavior is not None and talks(v.behavior)
        ]
        self.remote_talkers = [v for v in self.talkers if v not in self.served]
        self.served_talkers = [v for v in self.talkers if v in self.served]
        # Off (peers and samples handed over as they are): a perfect radio no behaviour talks on
        self.link_on = not self.link.perfect or bool(self.talkers)
        if self.link_on:
            for served in self.served.values():
                served.link = self.link
        self._sensors = [
            ConcentrationSensor.for_vehicle(scenario, k) for k in range(len(scenario.vehicles))
        ]
        self._link_states: list[VehicleState] = []  # the states of last_tick (link on)
        self._radio_in: dict[int, dict[str, RadioBatch]] = {}  # remote talkers' batches by tick
        self._radio_kept: dict[str, deque[bytes]] = {
            vid: deque(maxlen=RADIO_KEPT) for vid in self.served_talkers
        }
        self._radio_pubs = {
            vid: session.declare_publisher(self.keys.vehicle_radio(vid))
            for vid in self.served_talkers
        }
        self._radio_lock = threading.Lock()
        self._held: Tick | None = None  # a tick waiting for its peers' radio batches
        self._held_wall = 0.0
        self._asked = -1  # the held tick whose missing batches were asked for
        self._forcing = False  # step the held tick whatever is missing
        self._radio_wait_s = scenario.time.participant_timeout_s / 2
        self.batch_pub = session.declare_publisher(self.keys.autopilot_actuators(ctx.name))
        self.last_batch = b""  # the answer to last_tick (sent again if the tick repeats)
        self.last_tick = -1
        self.last_tick_wall = 0.0
        self._idle_status_wall = 0.0
        self.control_dt_s = 1.0 / ctx.scenario.time.control_hz
        # A stepped world's client decides between steps on what it has seen: a status every
        # tick lets it know it has seen the tick it paused at (agents.Swarm waits for that).
        stepped = ctx.scenario.time.mode == "stepped"
        self.status_period_s = 0.0 if stepped else options.status_period_s
        self.pending: PendingSensor | None = None
        self._declared: list[Any] = []  # subscribers and queryables, undeclared on close
        self._tokens: list[zenoh.LivelinessToken] = []
        self.router_outage = RouterOutage()  # readings are put again for subscribers back after it
        # Checkpoints (agents.resume): the keeper, and the tick part of the latest checkpoint.
        self.keeper: StateKeeper | None = None
        if options.checkpoint:
            period = ctx.scenario.time.checkpoint_period_s * ctx.scenario.time.control_hz
            self.keeper = StateKeeper(Path(options.checkpoint), round(period))
        self._snap_pending: PendingCheckpoint | None = None
        self._snap_tick = -1  # the tick of the state (last_tick runs ahead while resuming)
        # The commands handled since the oldest kept checkpoint — (the tick answered before
        # it, vehicle, command) — and the ticks a replay from a checkpoint passes again, the
        # one it went back to and the highest answered before: the replay handles those
        # commands again where they came (agents.resume).
        self._commands: list[HandledCommand] = []
        self._replay = (0, -1)
        self.node_name = ctx.name
        # Realtime: the vehicles that landed for want of ticks (docs/agents.md)
        self._realtime = ctx.scenario.time.mode == "realtime"
        self._state_lost: set[str] = set()

    # ------------------------------------------------------------------ set-up
    def declare(self, node_name: str) -> None:
        """Subscriber and queryables first, then the participants' tokens."""
        if self.keeper is not None:
            self.keeper.open(self._checkpoint())
        self._declared.append(watch_router(self.session, self.keys, self.router_outage))
        self._declared.append(
            self.session.declare_subscriber(self.keys.tick(), self._on_tick_sample)
        )
        if self.remote_talkers:
            self._declared.append(
                self.session.declare_subscriber(
                    self.keys.all_vehicle_radio(), self._on_radio_sample
                )
            )
        for vid in self.served_talkers:
            key = self.keys.vehicle_radio(vid)
            self._declared.append(self.session.declare_queryable(key, self._radio_query(vid)))
        for vid, served in self.served.items():
            key, handler = self.keys.vehicle_cmd(vid), self._command_handler(served)
            commands = serve_later(self.session, key, Command, handler)  # type: ignore[arg-type]
            self._declared.append(commands)
        for vid in self.served:
            name = autopilot_node(vid)
            if name != node_name:
                self._tokens.append(
                    self.session.liveliness().declare_token(self.keys.node_health(name))
                )
        for served in self.served.values():
            served.publish_status(force=True, period_s=self.status_period_s)

    def close(self) -> None:
        self.resender.close()
        if self.keeper is not None:
            self.keeper.close()
        for token in self._tokens:
            with suppress(zenoh.ZError):
                token.undeclare()
        for entity in self._declared:
            with suppress(zenoh.ZError):
                entity.undeclare()
        for served in self.served.values():
            with suppress(zenoh.ZError):
                served.readings_pub.close()

    # ------------------------------------------------------------------ bus callbacks
    def _on_tick_sample(self, sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "tick", log)
        if data is not None:
            self.inbox.put(TickArrived(data))

    def _on_radio_sample(self, sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "radio batch", log)
        if data is not None:
            self.inbox.put(RadioArrived(data))

    def _radio_query(self, vehicle_id: str) -> Callable[[zenoh.Query], None]:
        """Answer a query with the vehicle's last radio batches (on Zenoh's thread)."""

        def answer(query: zenoh.Query) -> None:
            with self._radio_lock:
                kept = list(self._radio_kept[vehicle_id])
            for data in kept:
                query.reply(query.key_expr, data)
            query.drop()

        return answer

    def _command_handler(self, served: _Served) -> Callable[[Incoming[Command]], None]:
        def handle(incoming: Incoming[Command]) -> None:
            self.inbox.put(CommandArrived(served, incoming))

        return handle

    # ------------------------------------------------------------------ the loop
    def run(self, stop: threading.Event) -> None:
        """Handle every event, one at a time and in arrival order, until ``stop``."""
        for event in self.inbox.events(stop):
            match event:
                case TickArrived(data):
                    self._on_tick_data(data)
                case CommandArrived():
                    self._on_command(event)
                    self._idle_statuses()
                    self._watch_ticks()
                case RadioArrived(data):
                    self._on_radio(data)
                case Idle():
                    self._idle_statuses()
                    self._watch_ticks()
                    self._catch_up()
                    if self._held is not None:
                        self._ask_for_radio()

    def _on_tick_data(self, data: bytes) -> None:
        try:
            tick = Tick.decode(data)
            if tick.tick < self.last_tick:
                # Time going back is a physics resumed from its checkpoint, and the whole
                # replay hangs on it: only a tick that is a SimTick in every state counts
                # (the partial view leaves the other vehicles' states unchecked).
                decode(data, SimTick)
        except MessageError as exc:
            key = self.keys.tick()
            refusals(log).refuse(key, f"bad tick on {key}", exc)
            return
        self._run_tick(tick)

    def _run_tick(self, tick: Tick) -> None:
        try:
            self.on_tick(tick)
        except Exception:  # never let one tick end the ticks; physics would drop us
            log.exception("tick %d failed", tick.tick)

    def _on_command(self, event: CommandArrived) -> None:
        served = event.served
        event.incoming.answer(lambda command: self._handle_command(served, command))

    def _handle_command(self, served: _Served, command: Command) -> CommandReply:
        reply = served.autopilot.handle(command)
        if self.keeper is not None:
            handled = HandledCommand(self.last_tick, served.vehicle_id, encode(command))
            self._commands.append(handled)
        served.publish_status(force=False, period_s=self.status_period_s)
        self._save()
        if not reply.accepted:
            log.info("%s: %s refused: %s", served.vehicle_id, type(command).__name__, reply.reason)
        return reply

    def _catch_up(self) -> None:
        """Put the kept readings again for a subscriber back after a router outage (it may
        have missed any of them: the dead router held some, others were put before it was
        back; subscribers keep one reading per vehicle and sim time)."""
        for vid, served in self.served.items():
            if n := served.readings_pub.catch_up(self.router_outage):
                log.info("%s: re-sending its last %d readings after the router's outage", vid, n)

    def _idle_statuses(self) -> None:
        """While no ticks arrive (physics not running), a status every IDLE_STATUS_PERIOD_S."""
        now = time.monotonic()
        if min(now - self.last_tick_wall, now - self._idle_status_wall) >= IDLE_STATUS_PERIOD_S:
            self._idle_status_wall = now
            for served in self.served.values():
                served.publish_status(force=True, period_s=0.0)

    def _watch_ticks(self) -> None:
        """Realtime mode: a vehicle whose ticks stopped for its ``state_loss_timeout_s`` (wall;
        at least ``time.participant_timeout_s``) lands (:meth:`Autopilot.state_lost`); its
        status says so."""
        if not self._realtime or self.last_tick < 0:
            return
        silent_s = time.monotonic() - self.last_tick_wall
        for vid, served in self.served.items():
            if vid in self._state_lost or silent_s < served.state_loss_s:
                continue
            self._state_lost.add(vid)
            log.warning(
                "%s: no tick for %.1f s after tick %d: vehicle state lost, landing",
                vid,
                silent_s,
                self.last_tick,
            )
            served.autopilot.state_lost(silent_s)
            served.publish_status(force=True, period_s=0.0)

    def _ticks_back(self, tick: Tick, silent_s: float) -> None:
        """Realtime: the first tick after an outage; how late it was, what was missed."""
        log.warning(
            "ticks again after %.1f s without: tick %d after tick %d (%d missed); still in "
            "their failsafe mode: %s",
            silent_s,
            tick.tick,
            self.last_tick,
            max(0, tick.tick - self.last_tick - 1),
            ", ".join(sorted(self._state_lost)),
        )
        self._state_lost.clear()

    def on_tick(self, tick: Tick) -> None:
        """Tick k: readings of the last sensor tick, each vehicle's step, one batch back."""
        held = self._held
        if held is not None and tick.tick > held.tick:
            # the physics went on (it had this process's answer to the held tick from before
            # a restart, or dropped it): the held tick first, with what can be had
            self._ask_for_radio(then_step=False)
            self._forcing = True
            try:
                self.on_tick(held)
            finally:
                self._forcing = False
        now = time.monotonic()
        if self._state_lost:
            self._ticks_back(tick, now - self.last_tick_wall)
        self.last_tick_wall = now
        self._catch_up()
        if self.keeper is not None:
            self._resume(tick)
        if tick.tick == self.last_tick:  # the start handshake repeats a tick: same answer
            self._held = None
            if self.last_batch:
                self.batch_pub.put(self.last_batch)
            return
        if self._radio_missing(tick):
            if self._held is None or self._held.tick != tick.tick:
                self._held_wall = now
            self._held = tick
            if now - self._held_wall >= RADIO_ASK_AFTER_S and self._asked != tick.tick:
                self._asked = tick.tick  # once from here (the ticks re-sent meanwhile)
                self._ask_for_radio()
            return
        self._held = None
        self._advance(tick)
        heard = self._link_tick(tick)
        self._collect_readings(tick)
        sensing = bool(tick.raw) and any(s.sensor.due(tick.tick) for s in self.served.values())
        commands = [c for s in self.served.values() if (c := s.step(tick, heard)) is not None]
        self._answer(tick, commands, sensing)
        if sensing:
            self.pending = PendingSensor(
                tick.tick, tick.sim_time_s, tick.heads(), tick.plume_queried
            )

    def _advance(self, tick: Tick) -> None:
        if self._replay[0] <= tick.tick - 1 <= self._replay[1]:
            self._replay_commands(tick.tick - 1)
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
            self.pending = None  # the sensor tick of a tick that is being replayed
        elif not self._realtime and 0 <= self.last_tick < tick.tick - 1:
            self._world_went_on(tick)
        self.last_tick = tick.tick
        if self.keeper is not None:
            self.keeper.before_tick(tick.tick)
            oldest = self.keeper.oldest_kept()
            if oldest is not None and self._commands and self._commands[0].after_tick < oldest:
                self._commands = [c for c in self._commands if c.after_tick >= oldest]

    def _world_went_on(self, tick: Tick) -> None:
        """Lockstep and stepped mode: ticks this process never answered were stepped, so the
        physics dropped it and flew its vehicles under its failsafe (hold, then land): land, as
        in realtime after a state loss; the mode stays until the pilot changes it."""
        missed = tick.tick - self.last_tick - 1
        log.warning(
            "tick %d after tick %d: %d ticks (%.2f s sim) were stepped without this autopilot "
            "(dropped): its vehicles were under the physics' failsafe; landing",
            tick.tick,
            self.last_tick,
            missed,
            missed * self.control_dt_s,
        )
        for served in self.served.values():
            served.autopilot.state_lost(missed * self.control_dt_s)
            served.publish_status(force=True, period_s=0.0)

    def _answer(self, tick: Tick, commands: list[ActuatorCommand], sensing: bool) -> None:
        """Checkpoint, then the batch of commands, then the statuses."""
        if commands:
            self.last_batch = encode(ActuatorBatch(tick=tick.tick, commands=commands))
        self._snap_tick = tick.tick
        if self.keeper is not None:  # saved before the answer goes out (agents.resume)
            self._snap_pending = self._pending_after(tick, sensing)
            self._save()
        self._publish_radio(tick.tick)
        if commands:
            self.batch_pub.put(self.last_batch)
        for served in self.served.values():
            served.publish_status(force=False, period_s=self.status_period_s)

    # ------------------------------------------------------------------ radio
    def _link_tick(self, tick: Tick) -> dict[str, list[VehicleState]] | None:
        """The radio's part of tick k, as the fused runner's: the behaviours' messages of
        tick k - 1 go out, what arrives by k is delivered, the states of k are sent; each
        vehicle's peers as heard (None: the link is off, every peer's state as it is)."""
        if not self.link_on:
            return None
        link = self.link
        states = tick.states()
        prev = self._link_states
        if prev and prev[0].tick == tick.tick - 1:
            got = self._radio_in.get(tick.tick - 1, {})
            for vid in self.remote_talkers:
                batch = got.get(vid)
                try:
                    link.put_outbox(vid, batch.messages if batch is not None else [])
                except RadioError as exc:
                    log.warning("tick %d: radio batch of %s dropped: %s", tick.tick, vid, exc)
                    link.put_outbox(vid, [])
            link.after_step(tick.tick - 1, prev)
        else:
            for vid in link.ids:
                link.mailboxes[vid].outbox = []
        for old in [t for t in self._radio_in if t < tick.tick]:
            del self._radio_in[old]
        self._link_states = states
        link.before_step(tick.tick)
        everyone = link.peers(tick.tick, states)
        return {s.vehicle_id: p for s, p in zip(states, everyone, strict=True)}

    def _radio_missing(self, tick: Tick) -> list[str]:
        """The remote talkers whose radio batch of tick k - 1 tick k waits for (lockstep and
        stepped clock; none after ``participant_timeout_s`` / 2 of waiting)."""
        if (
            not self.remote_talkers
            or self._realtime
            or self.last_tick < 0
            or self.last_tick != tick.tick - 1
        ):
            return []
        got = self._radio_in.get(self.last_tick, {})
        missing = [vid for vid in self.remote_talkers if vid not in got]
        if missing and self._held is not None and self._held.tick == tick.tick:
            waited_s = time.monotonic() - self._held_wall
            if waited_s > self._radio_wait_s or self._forcing:
                log.warning(
                    "tick %d: no radio batch of tick %d from %s after %.1f s: stepping without",
                    tick.tick,
                    self.last_tick,
                    ", ".join(missing),
                    waited_s,
                )
                return []
        return missing

    def _on_radio(self, data: bytes) -> None:
        self._keep_radio(data)
        held = self._held
        if held is not None and not self._radio_missing(held):
            self._run_tick(held)

    def _keep_radio(self, data: bytes) -> None:
        """A remote talker's batch, kept for the tick after its own."""
        try:
            batch = decode(data, RadioBatch)
        except MessageError as exc:
            key = self.keys.all_vehicle_radio()
            refusals(log).refuse(key, f"bad radio batch on {key}", exc)
            return
        if batch.sender in self.remote_talkers and batch.tick >= self.last_tick - 1:
            self._radio_in.setdefault(batch.tick, {})[batch.sender] = batch

    def _ask_for_radio(self, then_step: bool = True) -> None:
        """A held tick's missing batches, asked of their senders (kept there); ``then_step``:
        the tick goes on when they are all in, or after the wait."""
        held = self._held
        assert held is not None
        for vid in self._radio_missing(held):
            replies = self.session.get(
                self.keys.vehicle_radio(vid),
                timeout=RADIO_QUERY_TIMEOUT_S,
                consolidation=zenoh.ConsolidationMode.NONE,  # every kept batch, not the newest
            )
            for reply in replies:
                data = None if reply.ok is None else payload_or_none(reply.ok, "radio batch", log)
                if data is not None:
                    self._keep_radio(data)
        if then_step:
            self._run_tick(held)  # goes on if the batches are in, or it has waited enough

    def _publish_radio(self, tick: int) -> None:
        """Each served talker's messages of ``tick`` (an empty batch too: the receivers know
        then that they have all of them)."""
        for vid in self.served_talkers:
            data = encode(RadioBatch(sender=vid, tick=tick, messages=self.link.outbox(vid)))
            with self._radio_lock:
                self._radio_kept[vid].append(data)
            self._radio_pubs[vid].put(data)

    # ------------------------------------------------------------------ checkpoints
    def _pending_after(self, tick: Tick, sensing: bool) -> PendingCheckpoint | None:
        """The sensor tick awaited once ``tick`` is handled (see on_tick's end)."""
        p = self.pending
        if sensing:
            heads, sim_time, tick_no, by_physics = (
                tick.heads(),
                tick.sim_time_s,
                tick.tick,
                tick.plume_queried,
            )
        elif p is not None:
            heads, sim_time, tick_no, by_physics = p.states, p.sim_time_s, p.tick, p.by_physics
        else:
            return None
        return PendingCheckpoint(
            tick=tick_no,
            sim_time_s=sim_time,
            heads=[(h.vehicle_id, h.position_enu_m) for h in heads],
            by_physics=by_physics,
        )

    def _checkpoint(self) -> bytes:
        """The process's state now."""
        served = list(self.served.values())
        snap = ProcessCheckpoint(
            node=self.node_name,
            tick=self._snap_tick,
            vehicles=[capture(s.autopilot, s.sensor, s.flight.behavior_rng) for s in served],
            commands=[b"" for _ in served],
            batch=self.last_batch,
            status_times_s=[s.last_status_time_s for s in served],
            pending=self._snap_pending,
            link=self.link.snapshot() if self.link_on else b"",
            link_states=self._link_states if self.link_on else [],
            handled=self._commands,
        )
        return msgspec.msgpack.encode(snap)

    def _save(self) -> None:
        keeper = self.keeper
        if keeper is None:
            return
        try:
            keeper.save(self._checkpoint())
        except (CheckpointError, OSError) as exc:
            log.error("checkpoints off: %s", exc)
            self.keeper = None
        except Exception:  # a checkpoint must never cost the vehicle its ticks
            log.exception("checkpoints off: a checkpoint failed")
            self.keeper = None

    def _resume(self, tick: Tick) -> None:
        """Restore a checkpoint when this tick calls for one (agents.resume)."""
        keeper = self.keeper
        assert keeper is not None
        high = -1
        if self.last_tick < 0:
            snap = keeper.for_restart(tick.tick)
            how = "restarted process"
            latest = keeper.latest_found()
            if snap is not None and latest is not None:  # what it had handled: the replay's
                self._commands, high = list(latest.handled), latest.tick
        elif tick.tick < self.last_tick:
            snap = keeper.for_rewind(tick.tick)
            how = "physics resumed from its checkpoint"
            high = self.last_tick
        else:
            return
        if snap is None:
            return
        # The ticks a replay passes again: its state holds the commands up to its own tick.
        self._replay = (snap.tick + 1, max(self._replay[1], high))
        self._restore(snap)
        log.warning(
            "%s: restored the state of tick %d for tick %d (%s)",
            ", ".join(self.served),
            snap.tick,
            tick.tick,
            how,
        )

    def _replay_commands(self, after_tick: int) -> None:
        """The replay of a tick that went back is about to pass ``after_tick``: the commands
        handled there the first time are handled again (their replies went out then), so the
        replay flies as the first pass did."""
        again = [c for c in self._commands if c.after_tick == after_tick]
        for c in again:
            self.served[c.vehicle_id].autopilot.handle(decode(c.command, Command))  # type: ignore[arg-type]
        if again:
            log.info("tick %d: %d command(s) handled again in the replay", after_tick, len(again))
            self._save()

    def _restore(self, snap: ProcessCheckpoint) -> None:
        served = list(self.served.values())
        if [v.vehicle_id for v in snap.vehicles] != list(self.served):
            log.error("checkpoint of %s, not of this process's vehicles: not restored", snap.node)
            return
        for s, v, when in zip(served, snap.vehicles, snap.status_times_s, strict=True):
            restore(s.autopilot, s.sensor, v, s.flight.behavior_rng)
            s.last_status_time_s = when
            s.flight.new_readings = []
        self.last_batch = snap.batch
        self.last_tick = self._snap_tick = snap.tick
        if self.link_on and snap.link:
            self.link.restore(snap.link)
            self._link_states = list(snap.link_states)
            self._radio_in.clear()
        self._snap_pending = p = snap.pending
        self.pending = None
        if p is not None:
            heads = [StateHead(vid, pos) for vid, pos in p.heads]
            self.pending = PendingSensor(p.tick, p.sim_time_s, heads, p.by_physics)
        if self.keeper is not None:
            self.keeper.save(msgspec.msgpack.encode(snap))

    # ------------------------------------------------------------------ sensor
    def _collect_readings(self, tick: Tick) -> None:
        pending = self.pending
        if pending is None:
            return
        answer = tick.plume_values
        if pending.by_physics and (answer is None or answer.tick != pending.tick):
            return  # not the tick with the physics' answer (e.g. garbage on sim/tick): wait
        self.pending = None
        values = self._values(pending, answer)
        flights = [served.flight for served in self.served.values()]
        taken = take_readings(flights, pending.tick, pending.sim_time_s, pending.states, values)
        if self.link_on and not self.link.perfect:
            taken = self._heard_readings(tick.tick, pending, values, taken)
        for flight, reading in taken:
            self.served[flight.vehicle_id].readings_pub.put(encode(reading))

    def _heard_readings(
        self,
        tick: int,
        pending: PendingSensor,
        values: Sequence[float] | None,
        taken: list[tuple[Flight, ConcentrationReading]],
    ) -> list[tuple[Flight, ConcentrationReading]]:
        """The readings ``taken`` with their peers' samples as the radio brought them: every
        vehicle's sample of the sensor tick goes out (this process's readings, and the other
        vehicles' from the plume's answer for every position), as the fused runner sends
        them."""
        mine = {flight.vehicle_id: (flight, reading) for flight, reading in taken}
        located = {h.vehicle_id: (k, h) for k, h in reversed(list(enumerate(pending.states)))}
        everyone: list[ConcentrationReading] = []
        for vid, sensor in zip(self.link.ids, self._sensors, strict=True):
            if vid in mine:
                everyone.append(mine[vid][1])
                continue
            if vid not in located or not sensor.due(pending.tick):
                continue
            k, head = located[vid]
            true = values[k] if values is not None else None
            everyone.append(
                ConcentrationReading(
                    vehicle_id=vid,
                    sim_time_s=pending.sim_time_s,
                    position_enu_m=head.position_enu_m,
                    available=true is not None,
                    reported_g_m3=true,
                    true_g_m3=true,
                )
            )
        heard = self.link.readings(tick, self._link_states, everyone)
        out = []
        for reading in heard:
            if reading.vehicle_id in mine:
                flight = mine[reading.vehicle_id][0]
                flight.new_readings[-1] = reading
                out.append((flight, reading))
        return out

    @staticmethod
    def _values(pending: PendingSensor, answer: PlumeSample | None) -> list[float] | None:
        """The plume's values for the pending sensor tick, or None (no plume was alive, it did
        not answer in time, or answered wrong: the readings are unavailable)."""
        if not pending.by_physics or answer is None:
            return None
        values = answer.values_g_m3
        if values is not None and len(values) != len(pending.states):
            log.warning("physics sent %d values for %d points", len(values), len(pending.states))
            return None
        return values


def main(ctx: NodeContext) -> int:
    """Serve ``ctx.vehicle_ids`` until stopped."""
    if not ctx.vehicle_ids:
        log.error("autopilot: no vehicle to serve (--vehicle ID)")
        return 2
    try:
        options = role_options(AutopilotOptions, ctx)
        for vid in ctx.vehicle_ids:  # fail fast on a bad behaviour before joining the bus
            ctx.scenario.vehicle(vid)
    except (OptionError, KeyError) as exc:
        log.error("autopilot: %s", exc)
        return 2
    for vid in ctx.vehicle_ids:
        spec = ctx.scenario.vehicle(vid).behavior
        try:
            if spec is not None:
                talks(spec)
        except BehaviorError as exc:
            log.error("autopilot: %s", exc)
            return 2
    # Before the session opens (Zenoh reads it once, when its runtime starts); an operator's
    # own ZENOH_RUNTIME wins.
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)
    with NodeRuntime(ctx, role="autopilot", check_scenario_of="physics") as rt:
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
        refused = rt.refusal is not None
    return 2 if refused else 0
