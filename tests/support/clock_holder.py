"""A lockstep participant in the test process that holds the clock between ticks.

It is the autopilot of one parked scenario vehicle (its liveliness token ``autopilot-<id>``,
motors always off), so the physics waits for it every tick. It answers tick ``k`` only when
told, and only once every other vehicle's autopilot has answered ``k``: a command given while it
holds tick ``k`` takes effect at tick ``k + 1``, exactly where
:meth:`plumeswarm.experiments.fused.FusedRunner.command` puts it — in the plain lockstep mode,
without the
stepped clock's code.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence

import zenoh

from agents import SwarmError, VehicleCommander
from plumeswarm.experiments.demo import StateDigest
from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys, autopilot_node
from swarmbus.messages import ActuatorBatch, ActuatorCommand, Command, SimTick, VehicleState


class ClockError(RuntimeError):
    pass


class ClockHolder:
    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        vehicle_id: str,
        others: Sequence[str],
        rotor_count: int,
    ) -> None:
        self.session = session
        self.keys = keys
        self.vehicle_id = vehicle_id
        self.others = frozenset(others)
        self.rotor_count = rotor_count
        self.digest = StateDigest()
        self._states: dict[int, list[VehicleState]] = {}
        self._cond = threading.Condition()
        self._answered: dict[int, set[str]] = {}
        self._released = -1
        self._pub = session.declare_publisher(keys.autopilot_actuators(autopilot_node(vehicle_id)))
        self._subs = [
            session.declare_subscriber(keys.tick(), self._on_tick),
            session.declare_subscriber(keys.all_autopilot_actuators(), self._on_batch),
        ]
        self._token = session.liveliness().declare_token(
            keys.node_health(autopilot_node(vehicle_id))
        )

    def close(self) -> None:
        self._token.undeclare()
        for sub in self._subs:
            sub.undeclare()
        self._pub.undeclare()

    # ------------------------------------------------------------------ bus callbacks
    def _on_tick(self, sample: zenoh.Sample) -> None:
        try:
            tick = decode(sample.payload.to_bytes(), SimTick)
        except MessageError:
            return
        for state in tick.states:
            self.digest.add(encode(state))
        with self._cond:
            self._states.setdefault(tick.tick, tick.states)
            self._cond.notify_all()
        if tick.tick <= self._released:  # the start handshake repeats tick 0: answer again
            self.release(tick.tick)

    def _answer(self, commands: Sequence[ActuatorCommand]) -> None:
        with self._cond:
            for cmd in commands:
                if cmd.tick > self._released:
                    self._answered.setdefault(cmd.tick, set()).add(cmd.vehicle_id)
            self._cond.notify_all()

    def _on_batch(self, sample: zenoh.Sample) -> None:
        try:
            self._answer(decode(sample.payload.to_bytes(), ActuatorBatch).commands)
        except MessageError:
            return

    # ------------------------------------------------------------------ the clock
    def wait_answered(self, tick: int, timeout_s: float = 30.0) -> list[VehicleState]:
        """Until ``tick`` is published and every other autopilot answered it; its states."""
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not (tick in self._states and self.others <= self._answered.get(tick, set())):
                remaining = deadline - time.monotonic()
                if remaining <= 0.0:
                    missing = sorted(self.others - self._answered.get(tick, set()))
                    raise ClockError(
                        f"tick {tick} after {timeout_s:.0f} s: "
                        + ("no answer from " + ", ".join(missing) if missing else "not published")
                    )
                self._cond.wait(remaining)
            return self._states[tick]

    def release(self, tick: int) -> None:
        """Answer ``tick``: the physics steps on to ``tick + 1``."""
        cmd = ActuatorCommand(
            vehicle_id=self.vehicle_id, tick=tick, rotor_commands=[0.0] * self.rotor_count
        )
        with self._cond:
            if tick > self._released:
                self._released = tick
                for old in [k for k in self._states if k < tick]:
                    del self._states[old]
                for old in [k for k in self._answered if k <= tick]:
                    del self._answered[old]
        self._pub.put(encode(ActuatorBatch(tick=tick, commands=[cmd])))

    def run(
        self, last_tick: int, at_boundary: Callable[[int], Sequence[tuple[str, Command]]]
    ) -> None:
        """Ticks 0..``last_tick``; ``at_boundary(k)`` names the commands given after tick k
        (each must be accepted)."""
        for k in range(last_tick + 1):
            self.wait_answered(k)
            for vid, command in at_boundary(k):
                try:
                    VehicleCommander(self.session, self.keys, vid, 5.0).send(command)
                except SwarmError as exc:
                    raise ClockError(f"tick {k}: {vid} did not accept {command}: {exc}") from None
            if k < last_tick:
                self.release(k)
