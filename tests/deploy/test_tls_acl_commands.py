"""Least privilege on every plane, over real mTLS sessions through a router enforcing the
deployment's ACL (loopback, no root; as test_tls_acl.py): from every certificate of the hosts
file, a force disarm of uav1 reaches uav1's command queryable only from the gateway, an operator
and uav1's own autopilot, whatever key expression it is sent on; and each identity's forged
readings, statuses, restart notices and presence tokens are dropped, while what its role
produces gets through."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from deploy.hosts import Deployment, load_deployment
from deploy.security import host_identities, secure_network
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import Disarm
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.support.hosts import write_hosts
from tests.support.procs import run_cli, wait_until
from tests.support.tls_probe import forged_puts_seen, marker_of

KEYS = Keys("default")
ROLES = {
    "sim": ["router", "physics", "plume", "recorder", "viewer"],
    "agents": ["autopilot"],
    "gcs": ["gateway", "foxglove", "ros2"],
}
COMMANDERS = {"gateway.gcs", "operator.sim", "operator.agents", "operator.gcs",
              "autopilot-uav1.agents"}  # fmt: skip
# What each role produces, among the forged keys below (derived from the roles, not the ACL).
PRODUCES = {
    "physics": {KEYS.vehicle_state("uav1")},
    "plume": {KEYS.plume_sample()},
    "autopilot-uav1": {KEYS.vehicle_status("uav1"), KEYS.vehicle_concentration("uav1")},
    "operator": {KEYS.node_restart("physics")},
}
FORGED = [
    KEYS.vehicle_status("uav1"),
    KEYS.vehicle_concentration("uav1"),
    KEYS.vehicle_state("uav1"),
    KEYS.node_restart("physics"),
    KEYS.plume_sample(),
]
TOKENS = [KEYS.node_health("autopilot-uav1"), KEYS.node_health("physics")]
OWN_TOKEN = {"autopilot-uav1": TOKENS[0], "physics": TOKENS[1]}


def issue(tmp: Path) -> Deployment:
    """The hosts file of :data:`ROLES` (per-vehicle identities for uav1 and uav2) in ``tmp``,
    with the certificates of ``plumeswarm certs generate``."""
    hosts_file = write_hosts(
        tmp / "hosts.toml", f"tls/127.0.0.1:{free_tcp_port()}", ROLES, tls_certs="certs",
        per_vehicle_acl=True, vehicles={"agents": ["uav1", "uav2"]},
    )  # fmt: skip
    res = run_cli(["certs", "generate", "--hosts", str(hosts_file)])
    assert res.returncode == 0, res.stderr
    return load_deployment(hosts_file)


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Deployment]:
    dep = issue(tmp_path_factory.mktemp("tlsc"))
    router = NetworkConfig(mode="router", connect=[], listen=[dep.router])
    with open_session(secure_network(router, dep, "sim", "router", KEYS)):
        yield dep


def identities(dep: Deployment) -> list[tuple[str, str, str | None]]:
    """(host, role, node) of every certificate the hosts file issues."""
    out: list[tuple[str, str, str | None]] = []
    for h in host_identities(dep):
        for name in h.identities:
            role = name.partition(".")[0]
            if role.startswith("autopilot-"):
                out.append((h.host, "autopilot", role))
            else:
                out.append((h.host, role, None))
    return out


def sender(who: str) -> tuple[str, str, str | None]:
    """(host, role, node) of ``who``: a role of :data:`ROLES`, ``autopilot-<id>`` or an
    operator (of ``gcs``)."""
    host = {r: h for h, roles in ROLES.items() for r in roles}.get(who, "agents")
    role, node = ("autopilot", who) if who.startswith("autopilot-") else (who, None)
    return ("gcs" if who == "operator" else host), role, node


def client(dep: Deployment, host: str, role: str, node: str | None = None) -> NetworkConfig:
    base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
    return secure_network(base, dep, host, role, KEYS, node)


def test_only_the_gateway_an_operator_and_its_own_autopilot_reach_a_vehicles_commands(
    deployment: Deployment,
) -> None:
    dep = deployment
    everyone = identities(dep)
    assert len(everyone) == 13  # 5 + 3 + 3 roles, 2 vehicles instead of 1 autopilot, 3 operators
    arrived: list[str] = []
    lock = threading.Lock()

    def on_query(query: zenoh.Query) -> None:
        sender = query.attachment.to_string() if query.attachment is not None else "?"
        with lock:
            arrived.append(sender)
        query.reply(query.key_expr, b"disarmed")

    disarm = encode(Disarm(force=True))
    wide = [KEYS.vehicle_cmd("uav1"), f"{KEYS.prefix}/vehicle/*/cmd", KEYS.everything(), "**"]
    with open_session(client(dep, "agents", "autopilot", "autopilot-uav1")) as own:
        queryable = own.declare_queryable(KEYS.vehicle_cmd("uav1"), on_query)
        with open_session(client(dep, "gcs", "operator")) as op:  # the route is up
            wait_until(
                lambda: any(r.ok for r in op.get(KEYS.vehicle_cmd("uav1"), timeout=2.0)),
                30.0, "the operator's command answered",
            )  # fmt: skip
        arrived.clear()
        sessions = [open_session(client(dep, *who)) for who in everyone]
        try:
            pending = []
            for (host, role, node), s in zip(everyone, sessions, strict=True):
                name = f"{node or role}.{host}"
                for key in wide:
                    pending.append(s.get(key, payload=disarm, attachment=name, timeout=3.0))
            for replies in pending:
                list(replies)  # every get answered or timed out
            time.sleep(0.5)
        finally:
            for s in sessions:
                s.close()
            queryable.undeclare()
    with lock:
        senders = set(arrived)
    assert senders == COMMANDERS, f"commands of {sorted(senders - COMMANDERS)} arrived"


ROLE_SENDERS = ["physics", "plume", "recorder", "viewer", "autopilot-uav1", "autopilot-uav2",
                "gateway", "foxglove", "ros2", "operator"]  # fmt: skip


def forge(dep: Deployment, who: str) -> None:
    """From ``who``'s certificate, put on every key of :data:`FORGED` and declare every token of
    :data:`TOKENS`; an operator sees only what ``who``'s role produces (and its own token)."""
    host, role, node = sender(who)
    publisher = client(dep, host, role, node)
    listener = client(dep, "gcs", "operator")
    seen_tokens: list[str] = []
    with open_session(publisher) as ps:
        tokens = [ps.liveliness().declare_token(k) for k in TOKENS]
        result = forged_puts_seen(
            listener, publisher, KEYS, forged_keys=FORGED,
            marker_key=marker_of(dep, host, role, KEYS, node),
        )  # fmt: skip
        with open_session(listener) as ls:
            replies = ls.liveliness().get(KEYS.all_node_health(), timeout=3.0)
            seen_tokens = [str(r.ok.key_expr) for r in replies if r.ok is not None]
        for t in tokens:
            t.undeclare()
    assert result["marker"], "the marker never arrived: nothing was tested"
    assert set(result["seen"]) == PRODUCES.get(who, set())
    own = {OWN_TOKEN[who]} if who in OWN_TOKEN else set()
    assert set(seen_tokens) & set(TOKENS) == own


@pytest.mark.parametrize("who", ROLE_SENDERS)
def test_what_a_role_does_not_produce_is_dropped(deployment: Deployment, who: str) -> None:
    forge(deployment, who)
