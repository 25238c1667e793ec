"""A scripted lockstep participant for physics tests (not an autopilot).

``python -m tests.support.scripted_participant --connect EP --scenario F --vehicle a ...``
declares one ``autopilot-<id>`` liveliness token per vehicle and answers every ``sim/tick`` with
an ``ActuatorCommand`` per vehicle: a fixed throttle, the open-loop hover throttle, or a simple
altitude hold (so the commands depend on the states it receives). Each command goes as a
one-entry ``ActuatorBatch`` on its vehicle's own ``autopilot/autopilot-<id>/actuators`` (as K
one-vehicle processes would send); ``--batch`` sends them as one ``ActuatorBatch`` per tick on
the key of a process serving them all (``autopilot-<first>-plus<n>``). It can delay one
answer (for a time, or until a file exists) or stall for a while, and writes a JSON report on
exit: how many ticks it answered and whether it ever saw tick ``k + 1`` before it had answered
tick ``k`` (a lockstep violation).
"""

from __future__ import annotations

import argparse
import json
import math
import queue
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from swarmbus.codec import MessageError, decode, encode
from swarmbus.keys import Keys, autopilot_node, process_node
from swarmbus.messages import ActuatorBatch, ActuatorCommand, SimTick, VehicleState
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from swarmbus.vehicle_types import VehicleType, load_vehicle_type

G = 9.81


def hover_throttle(vt: VehicleType) -> float:
    omega = math.sqrt(vt.mass_kg * G / (len(vt.rotors) * vt.thrust_coeff_n_per_rad2_s2))
    return omega / vt.max_rotor_speed_rad_s


class Script:
    def __init__(self, args: argparse.Namespace) -> None:
        self.args = args
        scenario = load_scenario(args.scenario)
        self.keys = Keys(scenario.world.name)
        self.types = {v: load_vehicle_type(scenario.vehicle(v).type) for v in args.vehicle}
        self.stop = threading.Event()
        self.ticks: queue.SimpleQueue[bytes] = queue.SimpleQueue()
        self.lock = threading.Lock()
        self.answered = -1  # last tick answered
        self.answers = 0
        self.violations: list[str] = []
        self.delaying = False
        self.seen_while_delaying: list[int] = []
        self.delayed = False
        self.stalled_until_tick: int | None = None

    # ------------------------------------------------------------------ policy
    def rotor_commands(self, state: VehicleState) -> list[float]:
        vt = self.types[state.vehicle_id]
        n = len(vt.rotors)
        a = self.args
        if a.throttle is not None:
            return [a.throttle] * n
        hover = hover_throttle(vt)
        if a.altitude is None:
            return [hover] * n
        # Altitude hold: thrust ~ u^2, so scale u by sqrt of the wanted acceleration ratio.
        error = a.altitude - state.position_enu_m[2]
        accel = G + 2.0 * error - 2.5 * state.velocity_enu_m_s[2]
        u = hover * math.sqrt(max(0.0, min(2.0, accel / G)))
        return [max(0.0, min(1.0, u))] * n

    # ------------------------------------------------------------------ bus
    def on_tick(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        tick = decode(data, SimTick).tick
        with self.lock:
            if self.answered >= 0 and tick > self.answered + 1 and self.stalled_until_tick is None:
                self.violations.append(f"saw tick {tick} after answering only {self.answered}")
            if self.delaying:
                self.seen_while_delaying.append(tick)
        if self.args.inline:
            self.answer(data)
        else:
            self.ticks.put(data)

    def answer(self, data: bytes) -> None:
        try:
            msg = decode(data, SimTick)
        except MessageError:
            return
        a = self.args
        with self.lock:
            if a.follow_rewinds and msg.tick <= self.answered:
                # the physics resumed from a checkpoint (replay) or repeats a tick it holds:
                # answer it (again; a restarted physics may have missed the first answer)
                self.answered = msg.tick - 1
            if msg.tick <= self.answered and msg.tick != 0:
                return  # duplicate (tick 0 is re-sent during the handshake)
        if a.stall_at_tick is not None and msg.tick == a.stall_at_tick and not self.delayed:
            self.delayed = True
            with self.lock:
                self.stalled_until_tick = msg.tick
            self.stop.wait(a.stall_s)  # ticks keep arriving (and are ignored) meanwhile
            self.drain()
            return
        if a.delay_tick is not None and msg.tick == a.delay_tick and not self.delayed:
            self.delayed = True
            with self.lock:
                self.delaying = True
            self.hold(a.delay_s)
            with self.lock:
                self.delaying = False
        with self.lock:  # before the puts: tick k + 1 may arrive as soon as they are out
            self.answered = max(self.answered, msg.tick)
            self.answers += 1
        commands = [
            ActuatorCommand(
                vehicle_id=state.vehicle_id,
                tick=msg.tick,
                rotor_commands=self.rotor_commands(state),
            )
            for state in msg.states
            if state.vehicle_id in self.types
        ]
        if a.batch:
            self.batch_pub.put(encode(ActuatorBatch(tick=msg.tick, commands=commands)))
        else:
            for cmd in commands:
                self.pubs[cmd.vehicle_id].put(encode(ActuatorBatch(tick=msg.tick, commands=[cmd])))
        if a.max_tick is not None and msg.tick >= a.max_tick:
            self.stop.set()

    def hold(self, seconds: float) -> None:
        """The delay: ``seconds``, or until ``--release-file`` exists (within ``seconds``)."""
        release = self.args.release_file
        if release is None:
            self.stop.wait(seconds)
            return
        deadline = time.monotonic() + seconds
        while not Path(release).exists() and time.monotonic() < deadline:
            if self.stop.wait(0.02):
                return

    def drain(self) -> None:
        """After a stall: answer only the newest tick (skip the backlog)."""
        newest = None
        while True:
            try:
                newest = self.ticks.get_nowait()
            except queue.Empty:
                break
        with self.lock:
            self.answered = -1
        if newest is not None:
            self.answer(newest)

    def run(self) -> int:
        a = self.args
        net = NetworkConfig(connect=[a.connect], listen=["tcp/127.0.0.1:0"])
        with open_session(net) as session:
            self.pubs = {
                v: session.declare_publisher(self.keys.autopilot_actuators(autopilot_node(v)))
                for v in a.vehicle
            }
            node = process_node("autopilot", a.vehicle)
            self.batch_pub = session.declare_publisher(self.keys.autopilot_actuators(node))
            sub = session.declare_subscriber(self.keys.tick(), self.on_tick)
            tokens = [
                session.liveliness().declare_token(self.keys.node_health(autopilot_node(v)))
                for v in a.vehicle
            ]
            try:
                while not self.stop.is_set():
                    try:
                        data = self.ticks.get(timeout=0.1)
                    except queue.Empty:
                        continue
                    self.answer(data)
            finally:
                for token in tokens:
                    token.undeclare()
                sub.undeclare()
                self.write_report()
        return 0

    def write_report(self) -> None:
        if self.args.report is None:
            return
        with self.lock:
            report: dict[str, Any] = {
                "answered": self.answered,
                "answers": self.answers,
                "violations": self.violations,
                "seen_while_delaying": self.seen_while_delaying,
                "delayed": self.delayed,
            }
        Path(self.args.report).write_text(json.dumps(report))


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--connect", required=True)
    p.add_argument("--scenario", required=True)
    p.add_argument("--vehicle", action="append", required=True)
    p.add_argument("--throttle", type=float, default=None, help="fixed u for every rotor")
    p.add_argument("--altitude", type=float, default=None, help="hold this altitude (m)")
    p.add_argument("--delay-tick", type=int, default=None)
    p.add_argument("--delay-s", type=float, default=0.0)
    p.add_argument("--stall-at-tick", type=int, default=None)
    p.add_argument("--stall-s", type=float, default=0.0)
    p.add_argument("--max-tick", type=int, default=None, help="exit after answering this tick")
    p.add_argument("--inline", action="store_true", help="answer in the subscriber callback")
    p.add_argument("--report", default=None)
    p.add_argument("--batch", action="store_true", help="one ActuatorBatch per tick")
    p.add_argument("--release-file", default=None, help="the delay ends when this file exists")
    p.add_argument(
        "--follow-rewinds", action="store_true", help="answer again ticks the physics went back to"
    )
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    script = Script(parse(sys.argv[1:] if argv is None else argv))
    signal.signal(signal.SIGTERM, lambda *_: script.stop.set())
    signal.signal(signal.SIGINT, lambda *_: script.stop.set())
    return script.run()


if __name__ == "__main__":
    sys.exit(main())
