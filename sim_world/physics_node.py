"""The physics process (``plumeswarm node physics``): owner of simulated time and the lockstep.

Tick after tick it waits for every live participant's answer (:mod:`sim_world.inputs`), applies
the commands, steps the world and publishes the next tick (:mod:`sim_world.tick_out`), holding,
pacing, stepping and checkpointing on the way. See docs/physics.md ("Lockstep" and the sections
after it) and docs/architecture.md ("How a tick flows").
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Annotated, Self

import msgspec

from sim_world.checkpoint import CheckpointError
from sim_world.checkpointer import Checkpointer
from sim_world.drops import report_dropped
from sim_world.failsafe import CommandGaps
from sim_world.holds import Holds, UnreachableGrace
from sim_world.inputs import STOP_POLL_S, LockstepInputs
from sim_world.lockstep import Lockstep
from sim_world.pacing import Pacer
from sim_world.plume_part import PLUME
from sim_world.tick_out import TickOutput
from sim_world.world import World
from swarmbus.codec import encode
from swarmbus.messages import (
    Clock,
    SimTick,
    SpeedMode,
    StepReply,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import RoleOptions, role_main
from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

HANDSHAKE_REPUBLISH_S = 0.1  # tick 0 is re-sent until every participant has answered it
# Realtime: a dropped participant rejoins by answering one of the last ticks, not an old one.
REJOIN_WINDOW_TICKS = 12


class PhysicsOptions(RoleOptions, frozen=True, kw_only=True):
    """The physics role's options (``--set KEY=VALUE``); mode, speed factor and checkpoint
    period default to the scenario's ``[time]`` (:meth:`defaults`)."""

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
    def defaults(cls, scenario: Scenario) -> Self:
        """The scenario's ``[time]`` settings."""
        time_ = scenario.time
        return cls(
            mode=SpeedMode(time_.mode),
            speed_factor=time_.speed_factor,
            checkpoint_period_s=time_.checkpoint_period_s,
        )


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
        sensor_period = self.scenario.sensor.resolved().period_ticks
        timeout_s = self.scenario.time.participant_timeout_s
        realtime = options.mode == SpeedMode.REALTIME
        barrier = Lockstep(
            world.vehicle_ids,
            timeout_s,
            time.monotonic,
            periodic={PLUME: sensor_period},
            rejoin_window=REJOIN_WINDOW_TICKS if realtime else None,
        )
        # Restarts (lockstep): hold the tick for a process the launcher is restarting.
        grace_s = self.scenario.time.restart_grace_s if options.mode != SpeedMode.REALTIME else 0.0
        self.holds = Holds(grace_s, timeout_s, time.monotonic, HANDSHAKE_REPUBLISH_S)
        self.tick = 0
        self.checkpoints = Checkpointer(
            options.checkpoint_path, options.checkpoint_period_s, self.scenario.time.control_hz
        )
        self._stepped = options.mode == SpeedMode.STEPPED
        session = rt.session
        self.out = TickOutput(session, self.keys, world.vehicle_ids, sensor_period)
        self._clock_pub = session.declare_publisher(self.keys.clock())
        self.inputs = LockstepInputs(
            session,
            self.keys,
            barrier,
            self.holds,
            lambda: self.tick,
            self._step_refusal(),
            scenario_hash=rt.scenario_hash,
        )
        self._cond = self.inputs.cond  # the loop waits on what the inputs change
        self.barrier = barrier
        self.plume = self.inputs.plume
        self.clock_gate = self.inputs.clock_gate
        self.pacer = Pacer(time.monotonic, options.speed_factor, options.clock_period_s)
        self.silent = UnreachableGrace(
            self.scenario.time.unreachable_grace_s if options.mode == SpeedMode.LOCKSTEP else 0.0,
            time.monotonic,
        )
        self.dropped_total = 0  # participants dropped for a missed deadline (health detail)
        # A vehicle without its command (realtime: late; lockstep, stepped: dropped) holds, then
        # lands, under the physics' failsafe.
        self.gaps = CommandGaps(self.scenario, world.vehicle_ids)
        self._states: list[VehicleState] = []  # the current tick's (the failsafe's input)

    def _step_refusal(self) -> str | None:
        """Why ``clock/step`` is refused in this mode (None: stepped)."""
        if self._stepped:
            return None
        return (
            f"world {self.keys.world!r} runs in {self.options.mode} mode, not stepped "
            '(time.mode = "stepped" in the scenario, or plumeswarm up --stepped)'
        )

    def close(self) -> None:
        self.inputs.close()
        self.out.close()
        self.checkpoints.close()

    # ------------------------------------------------------------------ phases
    def run(self) -> int:
        resumed = self.checkpoints.resume(self.world)
        if resumed is not None:
            self.tick = resumed.tick
            self.plume.carried = resumed.plume_sample
        self.checkpoints.start(self.world, self.tick, self.plume.carried)
        self.rt.ready()
        startup_s = self.scenario.time.startup_timeout_s
        deadline = time.monotonic() + startup_s
        wait = self.options.wait_for_autopilots
        if wait and not self.inputs.wait_for_tokens(deadline, startup_s, self.rt.stop):
            return 0 if self.rt.stop.is_set() else 1  # a stop signal is not a failure
        # Who is alive now (the plume, for tick 0's sensor values), not when history arrives.
        self.inputs.presence.sync(timeout_s=min(2.0, max(0.1, deadline - time.monotonic())))
        self.inputs.admission.wait_settled()  # their scenario checked (sim_world.admission)
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
        log.info("%s", self.gaps.summary(self.tick))
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
                late = barrier.late() if remaining <= 0.0 else []
                if late and self.silent.hold(barrier, self.tick):
                    # late, not gone: wait for them; the ones whose token went are dropped now
                    self._drop([p for p in barrier.missing() if p not in late], barrier.timeout_s)
                    continue
                if remaining <= 0.0:
                    waited_s = self.silent.waited_s(self.tick, barrier.timeout_s)
                    self._drop(barrier.missing(), waited_s)
                    self.silent.dropped()
                    break
                self._cond.wait(min(remaining, STOP_POLL_S))
                if barrier.held or self.silent.holding(self.tick):
                    self._republish_held_tick()
            self.silent.report_back(barrier, self.tick)
            return barrier.commands()  # a new dict of the decoded (never mutated) lists

    def _drop(self, dropped: list[str], waited_s: float) -> None:
        """Tick's deadline passed: stop waiting for ``dropped`` (caller holds the lock)."""
        if not dropped:
            return
        held = self.barrier.held
        self.barrier.drop(dropped)
        self.dropped_total += len(dropped)
        then = "the physics' failsafe"
        report_dropped(self.tick, dropped, held, waited_s, self.holds.grace_s, then)

    # ------------------------------------------------------------------ stepped clock
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

    def _republish_held_tick(self) -> None:
        """During a hold, re-send the held tick (as in the start-up handshake) so the new
        process receives it; the others answer a repeated tick with the same command."""
        if self.holds.republish_due():
            self.out.put_tick()
            if self.holds.resend_states(self.tick):
                self.out.put_states()
        self.out.catch_up(self.inputs.router_outage)

    def _wait_for_recorder(self) -> None:
        """The recorder left (lockstep): hold the next tick until a recorder is back, and
        backfill it (docs/physics.md, "Restarts: the clock waits")."""
        t0 = time.monotonic()
        back = self.inputs.wait_for_recorder(self.rt.stop)
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

    def _apply(self, commands: Mapping[str, Sequence[float]]) -> None:
        commands = self.gaps.fill(self.tick, commands, self._states)
        for bad in self.world.apply_tick(commands):
            log.warning("tick %d: %s; motors off", self.tick, bad)

    # ------------------------------------------------------------------ output
    def _publish_tick(self, states: list[VehicleState]) -> None:
        """Tick k out (the barrier has begun it): its states and the plume's values of the
        last sensor tick; whether it waits for the plume's sample of its own positions."""
        with self._cond:
            queried = self.barrier.waits(PLUME)
            carried = self.plume.published(queried, len(states))
        self._states = states
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
        self.out.catch_up(self.inputs.router_outage)

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
            if self.inputs.intake.foreign_dropped:
                detail += f" foreign commands {self.inputs.intake.foreign_dropped}"
            if late := self.gaps.note():
                detail += f"; {late}"
            if self.checkpoints.note:
                detail += f"; {self.checkpoints.note}"
            self.rt.publish_health(sim_time_s=sim_time_s, detail=detail)


@role_main(PhysicsOptions, "physics")
def main(ctx: NodeContext, options: PhysicsOptions) -> int:
    """Entry point of the ``physics`` role."""
    with World(ctx.scenario) as world, NodeRuntime(ctx, role="physics") as rt:
        node = PhysicsNode(rt, world, options)
        try:
            return node.run()
        except CheckpointError as exc:
            log.error("%s", exc)
            return 2
        finally:
            node.close()
