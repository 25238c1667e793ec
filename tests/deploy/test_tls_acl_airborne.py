"""A force disarm of an airborne vehicle from every certificate but the gateway's, an operator's
and its own autopilot's, over real mTLS sessions (which enforce nothing themselves, as a forger's
would not) through a real ``plumeswarm node router`` enforcing the deployment's ACL (loopback, no
root; as test_tls_acl_commands.py), with a real physics and a real autopilot process flying
uav1: every disarm is refused and named in the router's log, and uav1 is still armed, holding,
at its altitude; the same disarm from the gateway's certificate then takes effect (so the
refusals were not vacuous)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from deploy.hosts import Deployment
from swarmbus.keys import Keys
from swarmbus.messages import CommandReply, Disarm, GetParams
from swarmbus.reqrep import request
from swarmbus.session import open_session
from tests.deploy.test_tls_acl_commands import COMMANDERS, client, identities, issue
from tests.deploy.test_tls_acl_refusals import refused, start_router
from tests.support.airborne import Flight, force_disarms_answered, take_off, watching
from tests.support.procs import Network, NodeProcs, wait_until

KEYS = Keys("default")
ALTITUDE_M = 10.0
SCENARIO = (
    '[world]\nname = "default"\nseed = 7\n[time]\nparticipant_timeout_s = 120.0\n'
    'startup_timeout_s = 120.0\n[[vehicles]]\nid = "uav1"\nspawn_enu_m = [0.0, 0.0, 0.0]\n'
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
    with NodeProcs(Network(0), scenario, log_dir=tmp) as procs:
        start_router(procs, tmp)
        with (
            open_session(client(dep, "gcs", "operator")) as op,
            watching(op, KEYS, ALTITUDE_M) as flight,
        ):
            secured = ["--hosts", str(hosts_file), "--listen", "tls/127.0.0.1:0"]
            procs.start_module("plumeswarm", "node", "physics", "--scenario", str(scenario),
                               *secured, "--host", "sim", label="physics")  # fmt: skip
            procs.start_module("plumeswarm", "node", "autopilot", "--vehicle", "uav1",
                               "--scenario", str(scenario), *secured, "--host", "agents",
                               label="uav1")  # fmt: skip
            take_off(op, flight, KEYS)
            yield dep, flight, tmp / "router.log"


def refused_and_logged(answered: list[str], others: list[str], router_log: Path) -> None:
    """Nobody answered the force disarms of ``others`` (``answered``: who was), and the router's
    log names each of them refusing uav1's command to its sender."""
    assert answered == [], f"the autopilot answered a force disarm from {sorted(set(answered))}"
    cmd = ("query", KEYS.vehicle_cmd("uav1"))
    wait_until(
        lambda: all(cmd in refused(router_log, name) for name in others),
        10.0, "the router's line for each refused disarm",
    )  # fmt: skip


def test_a_force_disarm_of_an_airborne_vehicle_from_any_other_certificate_is_refused(
    airborne: tuple[Deployment, Flight, Path],
) -> None:
    dep, flight, router_log = airborne
    everyone = identities(dep)
    names = {f"{node or role}.{host}": (host, role, node) for host, role, node in everyone}
    others = sorted(set(names) - COMMANDERS)
    # router, physics, plume, recorder, viewer, uav2's autopilot, foxglove, ros2
    assert len(others) == 8, others
    _, before = flight.newest()
    assert before is not None
    # Each sender's own session enforces nothing (as a forger's would): the router refuses.
    answered = force_disarms_answered({name: client(dep, *names[name]) for name in others}, KEYS)
    refused_and_logged(answered, others, router_log)
    # From before the first refused disarm to two simulated seconds after the last, uav1 held
    # at its altitude.
    lowest = flight.lowest_since(before, 2.0)
    assert flight.holding_at_altitude(), flight.newest()
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
    wait_until(flight.disarmed, 30.0, "uav1 disarmed by the gateway's certificate")
