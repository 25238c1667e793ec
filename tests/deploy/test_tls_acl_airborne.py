"""A force disarm of an airborne vehicle from every certificate but the gateway's, an operator's
and its own autopilot's, over real mTLS sessions (which enforce nothing themselves, as a forger's
would not) through a real ``plumeswarm node router`` enforcing the deployment's ACL (loopback, no
root; as test_tls_acl_commands.py), with a real physics and a real autopilot process flying
uav1: every disarm is refused and named in the router's log, and uav1 is still armed, holding,
at its altitude; the same disarm from the gateway's certificate then takes effect (so the
refusals were not vacuous)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from pathlib import Path

import msgspec
import pytest
import zenoh

from deploy.hosts import Deployment
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    CommandReply,
    Disarm,
    FlightMode,
    GetParams,
    Takeoff,
    VehicleState,
    VehicleStatus,
)
from swarmbus.reqrep import NoReply, request
from swarmbus.session import open_session
from tests.deploy.test_tls_acl_commands import COMMANDERS, client, identities, issue
from tests.deploy.test_tls_acl_refusals import refused, start_router
from tests.support.procs import Network, NodeProcs, wait_until

KEYS = Keys("default")
ALTITUDE_M = 10.0
SCENARIO = (
    '[world]\nname = "default"\nseed = 7\n[time]\nparticipant_timeout_s = 120.0\n'
    'startup_timeout_s = 120.0\n[[vehicles]]\nid = "uav1"\nspawn_enu_m = [0.0, 0.0, 0.0]\n'
)


class Flight:
    """What the operator's session sees of uav1: its newest status and every state."""

    def __init__(self) -> None:
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
            and state.position_enu_m[2] > ALTITUDE_M - 1.0
        )


@pytest.fixture(scope="module")
def airborne(
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[tuple[Deployment, Flight, Path]]:
    """uav1 armed and holding at ALTITUDE_M, flown by real physics and autopilot processes
    under mTLS + the ACL through a real router, taken off by an operator's certificate; and
    the router's log."""
    tmp = tmp_path_factory.mktemp("tlsair")
    dep = issue(tmp)
    hosts_file = tmp / "hosts.toml"
    scenario = tmp / "scenario.toml"
    scenario.write_text(SCENARIO)
    flight = Flight()
    with NodeProcs(Network(0), scenario, log_dir=tmp) as procs:
        start_router(procs, tmp)
        with open_session(client(dep, "gcs", "operator")) as op:
            subs = [
                op.declare_subscriber(KEYS.vehicle_status("uav1"), flight.on_status),
                op.declare_subscriber(KEYS.vehicle_state("uav1"), flight.on_state),
            ]
            secured = ["--hosts", str(hosts_file), "--listen", "tls/127.0.0.1:0"]
            procs.start_module("plumeswarm", "node", "physics", "--scenario", str(scenario),
                               *secured, "--host", "sim", label="physics")  # fmt: skip
            procs.start_module("plumeswarm", "node", "autopilot", "--vehicle", "uav1",
                               "--scenario", str(scenario), *secured, "--host", "agents",
                               label="uav1")  # fmt: skip

            def command(cmd: object) -> CommandReply | None:
                try:
                    return request(op, KEYS.vehicle_cmd("uav1"), cmd, CommandReply, 5.0)
                except NoReply:
                    return None

            wait_until(lambda: flight.newest()[1], 120.0, "uav1's state from the physics")
            armed = wait_until(lambda: command(Arm()), 60.0, "uav1 to answer the operator")
            assert armed.accepted, armed
            took_off = command(Takeoff(altitude_m=ALTITUDE_M))
            assert took_off is not None and took_off.accepted, took_off
            wait_until(flight.holding_at_altitude, 180.0, "uav1 holding at altitude", poll_s=0.2)
            yield dep, flight, tmp / "router.log"
            for s in subs:
                s.undeclare()


def test_a_force_disarm_of_an_airborne_vehicle_from_any_other_certificate_is_refused(
    airborne: tuple[Deployment, Flight, Path],
) -> None:
    dep, flight, router_log = airborne
    everyone = identities(dep)
    names = {f"{node or role}.{host}": (host, role, node) for host, role, node in everyone}
    others = sorted(set(names) - COMMANDERS)
    # router, physics, plume, recorder, viewer, uav2's autopilot, foxglove, ros2
    assert len(others) == 8, others
    disarm = encode(Disarm(force=True))
    wide = [KEYS.vehicle_cmd("uav1"), f"{KEYS.prefix}/vehicle/*/cmd", KEYS.everything(), "**"]
    _, before = flight.newest()
    assert before is not None
    answered: list[str] = []
    # Each sender's own session enforces nothing (as a forger's would): the router refuses.
    sessions = {
        name: open_session(msgspec.structs.replace(client(dep, *names[name]), access_control=None))
        for name in others
    }
    try:
        pending = [
            (name, s.get(key, payload=disarm, timeout=3.0))
            for name, s in sessions.items()
            for key in wide
        ]
        for name, replies in pending:
            answered += [name for r in replies if r.ok is not None]
    finally:
        for s in sessions.values():
            s.close()
    assert answered == [], f"the autopilot answered a force disarm from {sorted(set(answered))}"
    cmd = ("query", KEYS.vehicle_cmd("uav1"))
    wait_until(
        lambda: all(cmd in refused(router_log, name) for name in others),
        10.0, "the router's line for each refused disarm",
    )  # fmt: skip
    # Two simulated seconds after the last refused disarm, uav1 still holds at its altitude.
    t_end = before.sim_time_s + 2.0
    wait_until(
        lambda: (s := flight.newest()[1]) is not None and s.sim_time_s > t_end,
        60.0, "two more simulated seconds",
    )  # fmt: skip
    with flight.lock:
        since = [s for s in flight.states if s.sim_time_s >= before.sim_time_s]
    assert flight.holding_at_altitude(), flight.newest()
    lowest = min(s.position_enu_m[2] for s in since)
    assert lowest > ALTITUDE_M - 1.0, f"uav1 sank to {lowest:.2f} m while refused disarms came"

    # The positive control: each commanding certificate reaches the real autopilot, and the
    # gateway's force disarm, the same message, takes effect.
    for name in sorted(COMMANDERS):
        with open_session(client(dep, *names[name])) as s:
            reply = request(s, KEYS.vehicle_cmd("uav1"), GetParams(), CommandReply, 10.0)
            assert reply.accepted and reply.params, (name, reply)
    with open_session(client(dep, *names["gateway.gcs"])) as gw:
        reply = request(gw, KEYS.vehicle_cmd("uav1"), Disarm(force=True), CommandReply, 10.0)
    assert reply.accepted, reply
    wait_until(
        lambda: (st := flight.newest()[0]) is not None and not st.armed,
        30.0, "uav1 disarmed by the gateway's certificate",
    )  # fmt: skip
