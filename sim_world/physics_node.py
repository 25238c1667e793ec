"""The physics process (``plumeswarm node physics``): owner of simulated time and the lockstep.

Each control tick ``k`` it publishes all vehicle states in one ``SimTick`` on ``sim/tick`` and
each state on ``vehicle/<id>/state`` (only while a subscriber matches that key: most readers
take the tick, and N puts per tick that nobody receives cost real time), waits for every live
autopilot's ``ActuatorCommand`` for tick ``k`` (:class:`~sim_world.lockstep.Lockstep`) as an
entry of an autopilot process's ``ActuatorBatch`` on ``autopilot/<node>/actuators`` (one message
for the K vehicles it serves, K = 1 included; each entry counts as that vehicle's command, a bad
entry is dropped with a log line; on a one-vehicle node's key, ``autopilot-<id>``, an entry for
another vehicle is dropped, counted in the health detail and logged once per key) — applies them,
steps ``scenario.substeps`` physics steps and publishes tick ``k + 1``.
``sim/clock`` carries sim time and the achieved real-time factor about ten times a wall-clock
second.

The sensor's plume values: the plume service is a lockstep participant of the sensor ticks
(``sensor.period_ticks``). The physics publishes each sensor tick on ``sim/sensor`` too (the
same bytes; the plume reads that key, so the other ticks do not wake it); the plume answers with
a ``FieldSample`` on ``field/sample`` (every vehicle's concentration at that tick's positions);
the tick is complete when the autopilots' commands and the plume's sample are in, and the next
tick carries the sample (``SimTick.plume_values``), from which the autopilots build their
readings. The physics asks nothing: it waits for the plume as it waits for an autopilot
(:class:`~sim_world.lockstep.Lockstep`, a periodic participant), and holds the clock for a plume
service the launcher restarts as it does for an autopilot. ``SimTick.plume_queried`` says
whether the tick waits for the plume (a plume service is taking part).

With a ``checkpoint`` path it saves the world there every ``checkpoint_period_s`` of sim time
(:mod:`sim_world.checkpoint`) and, when that file exists at start, resumes from it instead of
the spawn: the lockstep handshake then runs on the checkpoint's tick, and the autopilots answer
it like any tick (sim time goes back by the replayed span; autopilots with snapshots restore
their state of the tick before and replay the same bits).

Options (``--set KEY=VALUE``): ``max_ticks`` (stop once this tick is published and answered),
``mode`` (lockstep|realtime|stepped), ``speed_factor``, ``wait_for_autopilots`` (true|false: start
without waiting for the configured autopilots), ``clock_period_s``, ``checkpoint`` (a file
path; empty: none), ``checkpoint_period_s`` (default ``time.checkpoint_period_s``; 0: never).

Stepped mode (``mode = stepped``): after each tick is published and answered the physics waits
for the clock holder's grant (``clock/step``, :mod:`sim_world.stepping`) before it applies the
tick's commands; it answers the grant once the granted tick is published and answered. In the
other modes ``clock/step`` answers with an error naming the mode.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated

import msgspec
import zenoh

from sim_world.checkpoint import CheckpointError
from sim_world.checkpointer import Checkpointer
from sim_world.holds import RECORDER, ROUTER, Holds
from sim_world.intake import ActuatorIntake
from sim_world.lockstep import Lockstep, participant_of
from sim_world.pacing import Pacer
from sim_world.plume_part import PLUME, PlumeParticipation, decode_answer, is_plume
from sim_world.stepping import SteppedClock, StepRefused
from sim_world.tick_out import TickOutput
from sim_world.world import World
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import autopilot_node
from swarmbus.messages import (
    Clock,
    RestartNotice,
    SimTick,
    SpeedMode,
    StepReply,
    StepRequest,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, RoleOptions, parse_options
from swarmbus.reqrep import Incoming, serve_later
from swarmbus.session import Presence

log = logging.getLogger(__name__)

HANDSHAKE_REPUBLISH_S = 0.1  # tick 0 is re-sent until every participant has answered it
STOP_POLL_S = 0.2  # longest wait between checks of the stop signal


class PhysicsOptions(RoleOptions, frozen=True, kw_only=True):
    """The physics role's options (``--set KEY=VALUE``); mode, speed factor and checkpoint
    period default to the scenario's ``[time]`` (:meth:`from_context`)."""

    mode: SpeedMode = SpeedMode.LOCKSTEP
    speed_factor: Annotated[float, msgspec.Meta(gt=0.0, le=1e6)] = 1.0
    max_ticks: Annotated[int, msgspec.Meta(ge=0)] | None = None
    wait_for_autopilots: bool = True
    clock_period_s: Annotated[float, msgspec.Meta(gt=0.0, le=1e6)] = 0.1
    checkpoint: str = ""  # empty: none
    checkpoint_period_s: Annotated[float, msgspec.Meta(ge=0.0, le=1e9)] = 1.0

    @property
    def checkpoint_path(self) -> Path | None:
        return Path(self.checkpoint) if self.checkpoint.strip() else None

    @classmethod
    def from_context(cls, ctx: NodeContext) -> PhysicsOptions:
        """``ctx.options`` over the scenario's defaults, or :class:`OptionError`."""
        time_ = ctx.scenario.time
        defaults = cls(
            mode=SpeedMode(time_.mode),
            speed_factor=time_.speed_factor,
            checkpoint_period_s=time_.checkpoint_period_s,
        )
        return parse_options(cls, ctx.options, defaults)


class PhysicsNode:
    """The physics loop over a :class:`World` and a :class:`NodeRuntime`'s session."""

    def __init__(self, rt: NodeRuntime, world: World, options: PhysicsOptions) -> None:
        self.rt = rt
        self.world = world
        self.options = options
        self.scenario = rt.ctx.scenario
        self.keys = rt.keys
        self.control_dt_s = 1.0 / self.scenario.time.control_hz
        self.substeps = self.scenario.substeps
        self._cond = threading.Condition()
        sensor_period = self.scenario.sensor.resolved().period_ticks
        self.barrier = Lockstep(
            world.vehicle_ids,
            self.scenario.time.participant_timeout_s,
            time.monotonic,
            periodic={PLUME: sensor_period},
        )
        self.tick = 0
        self.checkpoints = Checkpointer(
            options.checkpoint_path, options.checkpoint_period_s, self.scenario.time.control_hz
        )
        session = rt.session
        self.out = TickOutput(session, self.keys, world.vehicle_ids, sensor_period)
        self._clock_pub = session.declare_publisher(self.keys.clock())
        self._actuator_sub = session.declare_subscriber(
            self.keys.all_autopilot_actuators(), self._on_batch
        )
        self.intake = ActuatorIntake(world.vehicle_ids, self.keys.autopilot_node_of)
        self.plume = PlumeParticipation()  # the plume's part of the sensor ticks
        self._sample_sub = session.declare_subscriber(
            self.keys.plume_sample(), self._on_field_sample
        )
        # The stepped clock (served in every mode: the others answer with an error).
        self._stepped = options.mode == SpeedMode.STEPPED
        self.clock_gate: SteppedClock[Incoming[StepRequest]] = SteppedClock()
        self._step_queryable = serve_later(
            session, self.keys.clock_step(), StepRequest, self._on_step
        )
        # Restarts (lockstep): hold the tick for a process the launcher is restarting.
        grace_s = self.scenario.time.restart_grace_s if options.mode != SpeedMode.REALTIME else 0.0
        word_s = self.scenario.time.participant_timeout_s
        self.holds = Holds(grace_s, word_s, time.monotonic, HANDSHAKE_REPUBLISH_S)
        self._restart_sub = session.declare_subscriber(
            self.keys.all_node_restart(), self._on_restart_notice
        )
        self._presence = Presence(session, self.keys, self._on_presence)
        self.pacer = Pacer(time.monotonic, options.speed_factor, options.clock_period_s)
        self.dropped_total = 0  # participants dropped for a missed deadline (health detail)

    def close(self) -> None:
        self._presence.close()
        self._step_queryable.undeclare()
        self._restart_sub.undeclare()
        self._actuator_sub.undeclare()
        self._sample_sub.undeclare()
        self.out.close()
        self.checkpoints.close()

    # ------------------------------------------------------------------ bus callbacks
    def _on_presence(self, name: str, alive: bool) -> None:
        if is_plume(name):
            self._on_plume_presence(name, alive)
            return
        if name == ROUTER and self.holds.enabled:
            self._on_router_presence(alive)
            return
        if name == RECORDER and self.holds.enabled:
            with self._cond:
                self.holds.recorder_presence(alive)  # gone: wait for its word before the next tick
                self._cond.notify_all()
            return
        vid = participant_of(name, self.world.vehicle_ids)
        if vid is None:
            if not alive:
                with self._cond:
                    if self.clock_gate.released(name):
                        log.info("the stepped clock's holder %s left: the clock is free", name)
            return
        with self._cond:
            self._participant(vid, alive)
        log.info("autopilot of %s %s", vid, "arrived" if alive else "left")

    def _on_router_presence(self, alive: bool) -> None:
        """The router went (lockstep): whoever leaves with it is held for the grace, the
        recorder's hold too; its return ends the outage (held participants stay held until
        they answer, as after a restart)."""
        with self._cond:
            was_away = self.holds.router(self.barrier, alive, self.tick)
            self._cond.notify_all()
        if alive and was_away:
            log.warning("tick %d: the router is back", self.tick)
        elif not alive:
            log.warning(
                "tick %d: the router left: holding the clock for whoever leaves with it "
                "(grace %.1f s)",
                self.tick,
                self.holds.grace_s,
            )

    def _on_plume_presence(self, name: str, alive: bool) -> None:
        """Plume services are one participant: present while any of them is."""
        with self._cond:
            if self.plume.presence(name, alive):
                self._participant(PLUME, alive)
        log.info("plume service %s %s", name, "arrived" if alive else "left")

    def _participant(self, participant: str, alive: bool) -> None:
        """A participant's token came or went (the caller holds the lock)."""
        if alive:
            self.barrier.joined(participant)
        else:
            self.holds.leave(self.barrier, participant)
        self._cond.notify_all()

    def _on_field_sample(self, sample: zenoh.Sample) -> None:
        """The plume's answer to a sensor tick: counts like an autopilot's command."""
        answer = decode_answer(sample.payload.to_bytes(), sample.key_expr)
        if answer is None:
            return
        with self._cond:
            if self.barrier.receive(PLUME, answer.tick, ()):
                self.plume.answered(answer)
                if self.barrier.complete():
                    self._cond.notify_all()

    def _on_batch(self, sample: zenoh.Sample) -> None:
        tick, entries = self.intake.entries(str(sample.key_expr), sample.payload.to_bytes())
        if not entries:
            return
        with self._cond:
            barrier = self.barrier
            counted = False
            for vid, rotor_commands in entries:
                counted = barrier.receive(vid, tick, rotor_commands) or counted
            # Wake the loop once per tick, not once per command.
            if counted and barrier.complete():
                self._cond.notify_all()

    # ------------------------------------------------------------------ phases
    def run(self) -> int:
        resumed = self.checkpoints.resume(self.world)
        if resumed is not None:
            self.tick = resumed.tick
            self.plume.carried = resumed.plume_sample
        self.checkpoints.start(self.world, self.tick, self.plume.carried)
        self.rt.ready()
        deadline = time.monotonic() + self.scenario.time.startup_timeout_s
        if self.options.wait_for_autopilots and not self._wait_for_tokens(deadline):
            return 0 if self.rt.stop.is_set() else 1  # a stop signal is not a failure
        # Who is alive now (the plume, for tick 0's sensor values), not when history arrives.
        self._presence.sync(timeout_s=min(2.0, max(0.1, deadline - time.monotonic())))
        with self._cond:
            self.barrier.start()
            self.barrier.begin(self.tick, timeout_s=max(0.0, deadline - time.monotonic()))
        self._publish_tick(self.world.states(self.tick, self.world.sim_time_s))
        if not self._handshake():
            return 0 if self.rt.stop.is_set() else 1
        self.checkpoints.started()
        self.pacer.reset(self.world.sim_time_s)
        self._publish_clock(self.world.sim_time_s, force=True)
        return self._loop()

    def _wait_for_tokens(self, deadline: float) -> bool:
        with self._cond:
            while missing := self.barrier.missing_tokens():
                remaining = deadline - time.monotonic()
                if self.rt.stop.is_set():
                    return False
                if remaining <= 0.0:
                    log.error(
                        "autopilots missing after %.1f s: %s (no liveliness token %s)",
                        self.scenario.time.startup_timeout_s,
                        ", ".join(missing),
                        ", ".join(autopilot_node(v) for v in missing),
                    )
                    return False
                self._cond.wait(min(remaining, STOP_POLL_S))
        log.info("all %d autopilots present", len(self.world.vehicle_ids))
        return True

    def _handshake(self) -> bool:
        """Re-publish the first tick (0, or the checkpoint's) until every participant answered
        it (beats start-up loss)."""
        with self._cond:
            while not self.barrier.complete():
                if self.rt.stop.is_set():
                    return False
                if self.barrier.remaining_s() <= 0.0:
                    log.error(
                        "no answer to tick %d within the start-up timeout from: %s",
                        self.tick,
                        ", ".join(self.barrier.missing()),
                    )
                    return False
                self._cond.wait(min(HANDSHAKE_REPUBLISH_S, self.barrier.remaining_s()))
                if not self.barrier.complete():
                    self.out.put_tick()
        log.info("tick %d handshake done with %d participants", self.tick, len(self.barrier.active))
        return True

    def _loop(self) -> int:
        """Tick after tick: the commands of tick k, the step, tick k + 1 out."""
        paced = self.options.mode == SpeedMode.REALTIME
        while not self.rt.stop.is_set():
            commands = self._await_commands()
            if commands is None or not self._may_step():
                break
            with self._cond:
                self.plume.take(self.tick)
            self._apply(commands)
            self.world.step(self.substeps)
            self.tick += 1
            if self.tick >= self.checkpoints.next_tick:
                self.checkpoints.save(self.world, self.tick, self.plume.carried)
            sim_time = self.world.sim_time_s
            if paced and (delay_s := self.pacer.delay_s(sim_time)) > 0.0:
                self.rt.stop.wait(delay_s)
            states = self.world.states(self.tick, sim_time)
            if self.holds.recorder_lost:
                self._wait_for_recorder()
            with self._cond:
                self.barrier.begin(self.tick)
            self._publish_tick(states)
            self._maybe_publish_clock(sim_time)
        self._stopped()
        return 0

    def _may_step(self) -> bool:
        """Whether the answered tick may be stepped: granted (stepped mode), within the run's
        ``max_ticks`` and the scenario's duration."""
        if self._stepped and not self._await_grant():
            return False
        max_ticks = self.options.max_ticks
        if max_ticks is not None and self.tick >= max_ticks:
            return False
        duration_s = self.scenario.time.duration_s
        return not (duration_s > 0.0 and self.world.sim_time_s >= duration_s)

    def _stopped(self) -> None:
        """The last clock, the stepped clock's holder answered, the run's figures logged."""
        self._publish_clock(self.world.sim_time_s, force=True)
        with self._cond:
            abandoned = self.clock_gate.abandon()
        if abandoned is not None:
            abandoned.refuse("ticks", f"the world stopped at tick {self.tick}")
        wall = self.pacer.elapsed_s()
        log.info(
            "physics stopped at tick %d, sim %.3f s after %.3f s wall (%.0f ticks/s)",
            self.tick,
            self.world.sim_time_s,
            wall,
            self.tick / wall if wall > 0 else 0.0,
        )
        self.checkpoints.finish()

    def _await_commands(self) -> dict[str, Sequence[float]] | None:
        """Block until the current tick is complete or its deadline passed (then drop)."""
        with self._cond:
            barrier = self.barrier
            while not barrier.complete():
                if self.rt.stop.is_set():
                    return None
                remaining = barrier.remaining_s()
                if remaining <= 0.0:
                    held = barrier.held
                    dropped = barrier.expire()
                    self._report_dropped(held, dropped)
                    break
                self._cond.wait(min(remaining, STOP_POLL_S))
                if barrier.held:
                    self._republish_held_tick()
            return barrier.commands()  # a new dict of the decoded (never mutated) lists

    # ------------------------------------------------------------------ stepped clock
    def _on_step(self, incoming: Incoming[StepRequest]) -> None:
        request = incoming.request
        if not self._stepped:
            incoming.refuse(
                "mode",
                f"world {self.keys.world!r} runs in {self.options.mode} mode, not stepped "
                '(time.mode = "stepped" in the scenario, or plumeswarm up --stepped)',
            )
            return
        with self._cond:
            try:
                target = self.clock_gate.request(request.client, request.ticks, self.tick, incoming)
            except StepRefused as exc:
                refusal: StepRefused | None = exc
            else:
                refusal = None
                self._cond.notify_all()
        if refusal is not None:
            incoming.refuse(refusal.field, refusal.reason)
        else:
            log.debug("%s: step to tick %d", request.client, target)

    def _await_grant(self) -> bool:
        """Stepped mode, the current tick published and answered: answer the grant that ends
        here, then wait for the next one. False when stopped."""
        with self._cond:
            done = self.clock_gate.reached(self.tick)
        if done is not None:
            self._publish_clock(self.world.sim_time_s)  # where it pauses (health: as due)
            done.reply(StepReply(tick=self.tick, sim_time_s=self.world.sim_time_s))
        while not self.rt.stop.is_set():
            with self._cond:
                if self.clock_gate.may_advance(self.tick):
                    return True
                self._cond.wait(STOP_POLL_S)
            self._maybe_publish_clock(self.world.sim_time_s)  # clock and health while paused
        return False

    # ------------------------------------------------------------------ restarts
    def _on_restart_notice(self, sample: zenoh.Sample) -> None:
        """The launcher's word on a process that ended: hold or drop its vehicles."""
        try:
            notice = decode(sample.payload.to_bytes(), RestartNotice)
        except MessageError as exc:
            log.warning("ignoring restart notice on %s: %s", sample.key_expr, exc)
            return
        holds = self.holds
        if notice.role == RECORDER and holds.enabled:
            with self._cond:
                holds.recorder_notice(notice.restarting, notice.delay_s)
                self._cond.notify_all()
            return
        known = [PLUME] if notice.role == PLUME else notice.vehicles
        vids = [v for v in known if v in self.barrier.participants]
        if not vids or not holds.enabled:
            return
        with self._cond:
            held = holds.restart_notice(self.barrier, vids, notice.restarting, notice.delay_s)
            self._cond.notify_all()
        if held and notice.restarting:
            log.warning(
                "tick %d: holding the clock for %s: %s is being restarted (grace %.1f s)",
                self.tick,
                ", ".join(held),
                notice.node,
                notice.delay_s + holds.grace_s,
            )
        elif held:
            log.warning("%s will not be restarted: %s dropped", notice.node, ", ".join(held))

    def _republish_held_tick(self) -> None:
        """During a hold, re-send the held tick (as in the start-up handshake) so the new
        process receives it; the others answer a repeated tick with the same command."""
        if self.holds.republish_due():
            self.out.put_tick()
            if self.holds.resend_states(self.tick):
                self.out.put_states()

    def _wait_for_recorder(self) -> None:
        """The recorder left (lockstep): hold the next tick until a recorder is back — up to
        the participant timeout for the launcher's word, up to the grace if it restarts it —
        so that the new recorder records every tick from the first one it missed."""
        t0 = time.monotonic()
        with self._cond:
            self.holds.begin_recorder_wait()
            while not self.rt.stop.is_set():
                remaining = self.holds.recorder_wait_s()
                if remaining is None or remaining <= 0.0:
                    break
                self._cond.wait(min(remaining, STOP_POLL_S))
            back = self.holds.end_recorder_wait()
        if back:
            self._backfill()
        log.warning(
            "tick %d: held the clock %.2f s for the recorder: %s",
            self.tick,
            time.monotonic() - t0,
            "it is back" if back else "it did not come back",
        )

    def _backfill(self) -> None:
        """Re-send the recent ticks and states on ``sim/backfill/<key>`` for the new recorder:
        those published after the old one died and before its token's departure reached us
        never reached it (the recorder keeps those it has not got, by key and tick)."""
        self.out.backfill(self.holds.recent)
        log.info("re-sent the last %d ticks to the new recorder", len(self.holds.recent))

    def _report_dropped(self, held: frozenset[str], dropped: list[str]) -> None:
        self.dropped_total += len(dropped)
        vehicles = [v for v in dropped if v != PLUME]
        if vehicles:
            log.warning(
                "tick %d: dropped %s after %.2f s without actuators (motors off)",
                self.tick,
                ", ".join(vehicles),
                self.barrier.timeout_s,
            )
        if PLUME in dropped:
            log.warning(
                "tick %d: no plume sample after %.2f s: this sensor tick's readings are "
                "unavailable; the plume service takes part again once it answers a sensor tick",
                self.tick,
                self.barrier.timeout_s,
            )
        self._report_expired_holds(held, dropped)

    def _report_expired_holds(self, held: frozenset[str], dropped: list[str]) -> None:
        expired = [v for v in dropped if v in held and v != PLUME]
        if expired:
            log.warning(
                "tick %d: restart grace of %.1f s passed: %s dropped (motors off, failsafe)",
                self.tick,
                self.holds.grace_s,
                ", ".join(expired),
            )

    def _apply(self, commands: Mapping[str, Sequence[float]]) -> None:
        for bad in self.world.apply_tick(commands):
            log.warning("tick %d: %s; motors off", self.tick, bad)

    # ------------------------------------------------------------------ output
    def _publish_tick(self, states: list[VehicleState]) -> None:
        """Tick k out (the barrier has begun it): its states and the plume's values of the
        last sensor tick; whether it waits for the plume's sample of its own positions."""
        with self._cond:
            queried = self.barrier.waits(PLUME)
            carried = self.plume.published(queried, len(states))
        msg = SimTick(
            tick=self.tick,
            sim_time_s=self.world.sim_time_s,
            control_dt_s=self.control_dt_s,
            states=states,
            plume_queried=queried,
            plume_values=carried,
        )
        self.out.set(self.tick, encode(msg), states)
        self.out.put_tick()
        self.checkpoints.mark(self.tick)
        sent = self.out.put_states()
        self.holds.remember([(self.keys.tick(), self.out.payload), *sent])

    def _maybe_publish_clock(self, sim_time_s: float) -> None:
        now = self.pacer.clock_due()
        if now is not None:
            self._publish_clock(sim_time_s, now=now)

    def _publish_clock(self, sim_time_s: float, force: bool = False, now: float = 0.0) -> None:
        now = now or time.monotonic()
        real_time_factor = self.pacer.measure(sim_time_s, now)
        with self._cond:
            participants = sorted(self.barrier.active)
        self._clock_pub.put(
            encode(
                Clock(
                    tick=self.tick,
                    sim_time_s=sim_time_s,
                    mode=self.options.mode,
                    speed_factor=self.options.speed_factor,
                    real_time_factor=min(real_time_factor, 1e9),
                    participants=participants,
                )
            )
        )
        if self.pacer.health_due(now, force):
            detail = f"tick {self.tick} dropped {self.dropped_total} states {self.out.states_sent}"
            if self.intake.foreign_dropped:
                detail += f" foreign commands {self.intake.foreign_dropped}"
            if self.checkpoints.note:
                detail += f"; {self.checkpoints.note}"
            self.rt.publish_health(sim_time_s=sim_time_s, detail=detail)


def main(ctx: NodeContext) -> int:
    """Entry point of the ``physics`` role."""
    try:
        options = PhysicsOptions.from_context(ctx)
    except OptionError as exc:
        log.error("physics: %s", exc)
        return 2
    with World(ctx.scenario) as world, NodeRuntime(ctx, role="physics") as rt:
        node = PhysicsNode(rt, world, options)
        try:
            return node.run()
        except CheckpointError as exc:
            log.error("%s", exc)
            return 2
        finally:
            node.close()
