"""What arrives for the lockstep from the bus, on Zenoh's callback threads: tokens, actuator
batches, plume samples, restart notices, step requests and health (a participant whose scenario
hash is not the physics's is refused; a recorder that cannot write holds the clock), applied to
the barrier and its parts under the one condition the physics loop waits on.

See docs/physics.md, "Lockstep".
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence

import zenoh

from sim_world.admission import Admission
from sim_world.holds import RECORDER, ROUTER, Holds
from sim_world.intake import ActuatorIntake
from sim_world.lockstep import Lockstep, participant_of
from sim_world.plume_part import PLUME, PlumeParticipation, decode_answer, is_plume
from sim_world.stepping import SteppedClock, StepRefused
from swarmbus.catchup import RouterOutage
from swarmbus.codec import decode_or_none
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import NodeHealth, NodeState, RestartNotice, StepRequest
from swarmbus.reqrep import Incoming, serve_later
from swarmbus.session import Presence, payload_or_none

log = logging.getLogger(__name__)

STOP_POLL_S = 0.2  # longest wait between checks of the stop signal


class LockstepInputs:
    """The barrier, the holds, the plume's part and the stepped clock, fed from the bus; every
    change happens under :attr:`cond`, which is notified when the loop may have to act."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        barrier: Lockstep,
        holds: Holds,
        tick: Callable[[], int],
        step_refusal: str | None,
        scenario_hash: str = "",
    ) -> None:
        self.cond = threading.Condition()
        self.barrier = barrier
        self.holds = holds
        self.vehicle_ids: Sequence[str] = barrier.vehicle_ids
        self.intake = ActuatorIntake(barrier.vehicle_ids, keys.autopilot_node_of)
        self.plume = PlumeParticipation()  # the plume's part of the sensor ticks
        self.clock_gate: SteppedClock[Incoming[StepRequest]] = SteppedClock()
        self.router_outage = RouterOutage()  # states are put again for subscribers back after it
        self._tick = tick  # the physics' current tick (for the logs and step grants)
        self._step_refusal = step_refusal  # why clock/step is refused; None in stepped mode
        self._actuator_sub = session.declare_subscriber(
            keys.all_autopilot_actuators(), self._on_batch
        )
        self._sample_sub = session.declare_subscriber(keys.plume_sample(), self._on_field_sample)
        # The stepped clock is served in every mode: the others answer with an error.
        self._step_queryable = serve_later(session, keys.clock_step(), StepRequest, self._on_step)
        self._restart_sub = session.declare_subscriber(
            keys.all_node_restart(), self._on_restart_notice
        )
        self._recorder_failing = False  # the recorder's health says error
        self.admission = Admission(scenario_hash, lambda name: self._presence(name, True))
        self.presence = Presence(session, keys, self._on_presence)
        self._health_sub = session.declare_subscriber(keys.all_node_health(), self._on_health)

    def close(self) -> None:
        self.presence.close()
        self._health_sub.undeclare()
        self._step_queryable.undeclare()
        self._restart_sub.undeclare()
        self._actuator_sub.undeclare()
        self._sample_sub.undeclare()

    def wait_for_tokens(self, deadline: float, startup_s: float, stop: threading.Event) -> bool:
        """Wait until every configured vehicle's token is present; False (logged) after
        ``deadline`` (``startup_s`` after the start), or when stopped."""
        with self.cond:
            while missing := self.barrier.missing_tokens():
                remaining = deadline - time.monotonic()
                if stop.is_set():
                    return False
                if remaining <= 0.0:
                    log.error(
                        "autopilots missing after %.1f s: %s (no liveliness token %s)",
                        startup_s,
                        ", ".join(missing),
                        ", ".join(autopilot_node(v) for v in missing),
                    )
                    return False
                self.cond.wait(min(remaining, STOP_POLL_S))
        log.info("all %d autopilots present", len(self.vehicle_ids))
        return True

    def wait_for_recorder(self, stop: threading.Event) -> bool:
        """The recorder left: wait until a recorder is back — up to the participant timeout
        for the launcher's word, up to the grace if it restarts it — so that the new recorder
        records every tick from the first one it missed. Whether it is back."""
        with self.cond:
            self.holds.begin_recorder_wait()
            while not stop.is_set():
                remaining = self.holds.recorder_wait_s()
                if remaining is None or remaining <= 0.0:
                    break
                self.cond.wait(min(remaining, STOP_POLL_S))
            return self.holds.end_recorder_wait()

    def _on_health(self, sample: zenoh.Sample) -> None:
        what = f"health on {sample.key_expr}"
        data = payload_or_none(sample, what, log)
        health = None if data is None else decode_or_none(data, NodeHealth, what, log)
        if health is None:
            return
        if health.name == RECORDER:
            self._on_recorder_health(health)
        self.admission.health(health)

    def _on_recorder_health(self, health: NodeHealth) -> None:
        """A recorder that cannot write (disk full) holds the clock as a restarting one."""
        if not self.holds.enabled:
            return
        failing = health.state is NodeState.ERROR
        if failing == self._recorder_failing or health.state is NodeState.STOPPING:
            return
        self._recorder_failing = failing
        with self.cond:
            self.holds.recorder_error(failing)
            self.cond.notify_all()
        if failing:
            log.warning("the recorder cannot write (%s): holding the clock for it", health.detail)

    def _on_presence(self, name: str, alive: bool) -> None:
        """A token came or went: a participant's arrival counts once its scenario is checked."""
        participant = PLUME if is_plume(name) else participant_of(name, self.vehicle_ids)
        if participant is not None:
            admitted = (
                self.admission.arrival(participant, name)
                if alive
                else self.admission.departure(participant)
            )
            if not admitted:
                return
        self._presence(name, alive)

    def _presence(self, name: str, alive: bool) -> None:
        if is_plume(name):
            self._on_plume_presence(name, alive)
            return
        if name == ROUTER:
            self.router_outage.router(alive)
        if name == ROUTER and self.holds.enabled:
            self._on_router_presence(alive)
            return
        if name == RECORDER and self.holds.enabled:
            with self.cond:
                self.holds.recorder_presence(alive)  # gone: wait for its word before the next tick
                self.cond.notify_all()
            return
        vid = participant_of(name, self.vehicle_ids)
        if vid is None:
            if not alive:
                with self.cond:
                    if self.clock_gate.released(name):
                        log.info("the stepped clock's holder %s left: the clock is free", name)
            return
        with self.cond:
            self._participant(vid, alive)
        log.info("autopilot of %s %s", vid, "arrived" if alive else "left")

    def _on_router_presence(self, alive: bool) -> None:
        """The router went (lockstep): whoever leaves with it is held for the grace, the
        recorder's hold too; its return ends the outage (held participants stay held until
        they answer, as after a restart)."""
        with self.cond:
            was_away = self.holds.router(self.barrier, alive, self._tick())
            self.cond.notify_all()
        if alive and was_away:
            log.warning("tick %d: the router is back", self._tick())
        elif not alive:
            log.warning(
                "tick %d: the router left: holding the clock for whoever leaves with it "
                "(grace %.1f s)",
                self._tick(),
                self.holds.grace_s,
            )

    def _on_plume_presence(self, name: str, alive: bool) -> None:
        """Plume services are one participant: present while any of them is."""
        with self.cond:
            if self.plume.presence(name, alive):
                self._participant(PLUME, alive)
        log.info("plume service %s %s", name, "arrived" if alive else "left")

    def _participant(self, participant: str, alive: bool) -> None:
        """A participant's token came or went (the caller holds the lock)."""
        if alive:
            self.barrier.joined(participant)
        else:
            self.holds.leave(self.barrier, participant)
        self.cond.notify_all()

    def _on_field_sample(self, sample: zenoh.Sample) -> None:
        """The plume's answer to a sensor tick: counts like an autopilot's command."""
        data = payload_or_none(sample, "plume sample", log)
        answer = None if data is None else decode_answer(data, sample.key_expr)
        if answer is None:
            return
        with self.cond:
            if self.barrier.receive(PLUME, answer.tick, ()):
                self.plume.answered(answer)
                if self.barrier.complete():
                    self.cond.notify_all()

    def _on_batch(self, sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "actuator batch", log)
        if data is None:
            return
        tick, entries = self.intake.entries(str(sample.key_expr), data)
        if not entries:
            return
        with self.cond:
            barrier = self.barrier
            counted = False
            for vid, rotor_commands in entries:
                counted = barrier.receive(vid, tick, rotor_commands) or counted
            # Wake the loop once per tick, not once per command.
            if counted and barrier.complete():
                self.cond.notify_all()

    def _on_restart_notice(self, sample: zenoh.Sample) -> None:
        """The launcher's word on a process that ended: hold or drop its vehicles."""
        key = str(sample.key_expr)
        data = payload_or_none(sample, "restart notice", log)
        notice = (
            None
            if data is None
            else decode_or_none(data, RestartNotice, "restart notice", log, key)
        )
        if notice is None:
            return
        holds = self.holds
        if notice.role == RECORDER and holds.enabled:
            with self.cond:
                holds.recorder_notice(notice.restarting, notice.delay_s)
                self.cond.notify_all()
            return
        known = [PLUME] if notice.role == PLUME else notice.vehicles
        vids = [v for v in known if v in self.barrier.participants]
        if not vids or not holds.enabled:
            return
        with self.cond:
            held = holds.restart_notice(self.barrier, vids, notice.restarting, notice.delay_s)
            self.cond.notify_all()
        if held and notice.restarting:
            log.warning(
                "tick %d: holding the clock for %s: %s is being restarted (grace %.1f s)",
                self._tick(),
                ", ".join(held),
                notice.node,
                notice.delay_s + holds.grace_s,
            )
        elif held:
            log.warning("%s will not be restarted: %s dropped", notice.node, ", ".join(held))

    def _on_step(self, incoming: Incoming[StepRequest]) -> None:
        request = incoming.request
        if self._step_refusal is not None:
            incoming.refuse("mode", self._step_refusal)
            return
        with self.cond:
            paused = self._tick()
            try:
                target = self.clock_gate.request(request.client, request.ticks, paused, incoming)
            except StepRefused as exc:
                refusal: StepRefused | None = exc
            else:
                refusal = None
                self.cond.notify_all()
        if refusal is not None:
            incoming.refuse(refusal.field, refusal.reason)
        else:
            log.debug("%s: step to tick %d", request.client, target)
