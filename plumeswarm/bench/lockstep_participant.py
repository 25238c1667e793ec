"""A lockstep participant for ``plumeswarm.bench.physics``: a stand-in for the autopilots, not a
vehicle.

``python -m plumeswarm.bench.lockstep_participant --connect EP --scenario F --vehicle a --vehicle b
...
[--throttle U]`` declares one autopilot liveliness token per vehicle and answers
every ``sim/tick``, inside the subscriber callback, with one ``ActuatorBatch``: every rotor of
every vehicle at ``--throttle``, or (without it) at the vehicle type's open-loop hover throttle.
It does no control, so the bench measures the physics and the handshake, not an autopilot.
"""

from __future__ import annotations

import argparse
import math
import signal
import sys
import threading

from deploy.ceiling import answer_ticks, participant_tokens
from swarmbus.keys import Keys, process_node
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from swarmbus.vehicle_types import VehicleType, load_vehicle_type

G = 9.81


def hover_throttle(vt: VehicleType) -> float:
    """The rotor command whose thrust carries the weight: T = k ω² per rotor, u = ω / ω_max."""
    omega = math.sqrt(vt.mass_kg * G / (len(vt.rotors) * vt.thrust_coeff_n_per_rad2_s2))
    return omega / vt.max_rotor_speed_rad_s


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        prog="python -m plumeswarm.bench.lockstep_participant", description=__doc__
    )
    p.add_argument("--connect", required=True, help="the router endpoint")
    p.add_argument("--scenario", required=True, help="the scenario file")
    p.add_argument("--vehicle", action="append", required=True, help="a vehicle id (repeat)")
    p.add_argument("--throttle", type=float, default=None, help="fixed u for every rotor")
    a = p.parse_args(sys.argv[1:] if argv is None else argv)
    scenario = load_scenario(a.scenario)
    keys = Keys(scenario.world.name)
    rotors: dict[str, list[float]] = {}
    for vid in a.vehicle:
        vt = load_vehicle_type(scenario.vehicle(vid).type)
        u = hover_throttle(vt) if a.throttle is None else a.throttle
        rotors[vid] = [u] * len(vt.rotors)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    net = NetworkConfig(connect=[a.connect], listen=["tcp/127.0.0.1:0"])
    with open_session(net) as session:
        name = process_node("autopilot", a.vehicle)
        sub = answer_ticks(session, keys, name, rotors)
        tokens = participant_tokens(session, keys, rotors)
        stop.wait()
        sub.undeclare()
        for token in tokens:
            token.undeclare()
    return 0


if __name__ == "__main__":
    sys.exit(main())
