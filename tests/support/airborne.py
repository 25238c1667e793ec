"""An airborne vehicle under mTLS + the ACL, and force disarms sent to it from certificates
whose sessions enforce nothing themselves (as a forger's would not): what an operator's session
sees of the vehicle (:class:`Flight`), its takeoff, the disarms, and how low it went meanwhile.

As a script (inside a network namespace), the whole check: an operator of ``HOST`` takes uav1
off to ``ALTITUDE_M``, each ``SENDER`` identity (``role.host``, ``autopilot-<id>.host``) sends
``Disarm(force=True)`` on every key expression of :func:`wide_keys`, then the gateway's
certificate sends the same disarm; prints one JSON object::

    python -m tests.support.airborne HOSTS_FILE SCENARIO HOST ALTITUDE_M SENDER...
"""

from __future__ import annotations

import json
import sys
import threading
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from deploy.hosts import Deployment, load_deployment
from deploy.security import secure_network
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    CommandReply,
    Disarm,
    FlightMode,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.reqrep import NoReply, request
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from tests.support.procs import wait_until

VEHICLE = "uav1"


class Flight:
    """What an operator's session sees of uav1: its newest status and every state."""

    def __init__(self, altitude_m: float) -> None:
        self.altitude_m = altitude_m
        self.lock = threading.Lock()
        self.status: VehicleStatus | None = None
        self.states: list[VehicleState] = []

    def on_status(self, sample: zenoh.Sample) -> None:
        s = decode(sample.payload.to_bytes(), VehicleStatus)
        with self.lock:
            self.status = s

    def on_state(self, sample: zenoh.Sample) -> None:
        s = decode(sample.payload.to_bytes(), VehicleState)
        with self.lock:
            self.states.append(s)

    def newest(self) -> tuple[VehicleStatus | None, VehicleState | None]:
        with self.lock:
            return self.status, (self.states[-1] if self.states else None)

    def holding_at_altitude(self) -> bool:
        status, state = self.newest()
        return (
            status is not None
            and state is not None
            and status.armed
            and status.mode == FlightMode.HOLD
            and state.position_enu_m[2] > self.altitude_m - 1.0
        )

    def lowest_since(self, since: VehicleState, sim_s: float) -> float:
        """Waits ``sim_s`` more simulated seconds; the lowest altitude of uav1 from the state
        ``since`` to then."""
        _, now = self.newest()
        assert now is not None, "no state of uav1 yet"
        t_end = now.sim_time_s + sim_s
        wait_until(
            lambda: (s := self.newest()[1]) is not None and s.sim_time_s > t_end,
            60.0, f"{sim_s} more simulated seconds",
        )  # fmt: skip
        with self.lock:
            states = [s for s in self.states if s.sim_time_s >= since.sim_time_s]
        return min(s.position_enu_m[2] for s in states)

    def disarmed(self) -> bool:
        status = self.newest()[0]
        return status is not None and not status.armed


@contextmanager
def watching(session: zenoh.Session, keys: Keys, altitude_m: float) -> Iterator[Flight]:
    """uav1's status and states as ``session`` receives them."""
    flight = Flight(altitude_m)
    subs = [
        session.declare_subscriber(keys.vehicle_status(VEHICLE), flight.on_status),
        session.declare_subscriber(keys.vehicle_state(VEHICLE), flight.on_state),
    ]
    try:
        yield flight
    finally:
        for s in subs:
            s.undeclare()


def take_off(op: zenoh.Session, flight: Flight, keys: Keys) -> None:
    """Arms uav1 and takes it off from ``op`` (an operator's session); returns once it holds
    at the flight's altitude."""

    def command(cmd: object) -> CommandReply | None:
        try:
            return request(op, keys.vehicle_cmd(VEHICLE), cmd, CommandReply, 5.0)
        except NoReply:
            return None

    wait_until(lambda: flight.newest()[1], 120.0, "uav1's state from the physics")
    armed = wait_until(lambda: command(Arm()), 60.0, "uav1 to answer the operator")
    assert armed.accepted, armed
    took_off = command(Takeoff(altitude_m=flight.altitude_m))
    assert took_off is not None and took_off.accepted, took_off
    wait_until(flight.holding_at_altitude, 180.0, "uav1 holding at altitude", poll_s=0.2)


def wide_keys(keys: Keys) -> list[str]:
    """uav1's command key and every wider expression that includes it."""
    return [keys.vehicle_cmd(VEHICLE), f"{keys.prefix}/vehicle/*/cmd", keys.everything(), "**"]


def force_disarms_answered(senders: Mapping[str, NetworkConfig], keys: Keys) -> list[str]:
    """From each sender's certificate, on a session that enforces no ACL of its own,
    ``Disarm(force=True)`` on every key of :func:`wide_keys`; the senders that got an answer
    (once per answer)."""
    disarm = encode(Disarm(force=True))
    sessions = {
        name: open_session(msgspec.structs.replace(net, access_control=None))
        for name, net in senders.items()
    }
    answered: list[str] = []
    try:
        pending = [
            (name, s.get(key, payload=disarm, timeout=3.0))
            for name, s in sessions.items()
            for key in wide_keys(keys)
        ]
        for name, replies in pending:
            answered += [name for r in replies if r.ok is not None]
    finally:
        for s in sessions.values():
            s.close()
    return answered


def client_of(dep: Deployment, name: str, keys: Keys) -> NetworkConfig:
    """A client of the router with the certificate of identity ``name`` (``role.host``,
    ``autopilot-<id>.host``)."""
    first, _, host = name.rpartition(".")
    role, node = ("autopilot", first) if first.startswith("autopilot-") else (first, None)
    base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
    return secure_network(base, dep, host, role, keys, node)


def main(argv: list[str]) -> int:
    """``HOSTS_FILE SCENARIO HOST ALTITUDE_M SENDER...``: see the module's docstring."""
    hosts_file, scenario, host, altitude = argv[:4]
    dep = load_deployment(Path(hosts_file))
    keys = Keys(load_scenario(Path(scenario)).world.name)
    senders = {name: client_of(dep, name, keys) for name in argv[4:]}
    result: dict[str, Any] = {}
    with (
        open_session(client_of(dep, f"operator.{host}", keys)) as op,
        watching(op, keys, float(altitude)) as flight,
    ):
        take_off(op, flight, keys)
        _, before = flight.newest()
        assert before is not None
        result["answered"] = force_disarms_answered(senders, keys)
        result["lowest_m"] = flight.lowest_since(before, 2.0)
        result["holding"] = flight.holding_at_altitude()
        # The positive control: the same message from the gateway's certificate.
        with open_session(client_of(dep, "gateway.gcs", keys)) as gw:
            reply = request(gw, keys.vehicle_cmd(VEHICLE), Disarm(force=True), CommandReply, 10.0)
        result["gateway_accepted"] = reply.accepted
        wait_until(flight.disarmed, 30.0, "uav1 disarmed by the gateway's certificate")
        result["disarmed"] = flight.disarmed()
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
