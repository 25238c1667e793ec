"""A refused message is logged where it is refused: a real ``plumeswarm node router`` under the
deployment's mTLS + ACL (loopback, no root; the identities of test_tls_acl_commands.py) drops
each role identity's forged readings, statuses, restart notices and liveliness tokens, and its
log names each one with the key and the identity that sent it, and nothing of what the role
may send."""

from __future__ import annotations

import re
import time
from collections.abc import Iterator, Sequence
from pathlib import Path

import psutil
import pytest

from deploy.hosts import Deployment
from swarmbus.keys import Keys
from swarmbus.session import NetworkConfig, open_session
from tests.deploy.test_tls_acl_commands import (
    FORGED,
    OWN_TOKEN,
    PRODUCES,
    ROLE_SENDERS,
    TOKENS,
    forge,
    issue,
    sender,
)
from tests.support.procs import Network, NodeProcs, wait_until
from tests.support.tls_probe import join_error, stranger_tls

KEYS = Keys("default")


def start_router(procs: NodeProcs, tmp: Path, prefix: Sequence[str] = ()) -> Path:
    """``plumeswarm node router`` of the hosts file in ``tmp`` (as ``router.sim``), once it
    listens; its log. ``prefix``: what runs it (as for ``NodeProcs.start_module``)."""
    log = tmp / "router.log"
    procs.start_module(
        "plumeswarm", "-v", "node", "router", "--hosts", str(tmp / "hosts.toml"),
        "--host", "sim", label="router", prefix=prefix,
    )  # fmt: skip
    wait_until(lambda: "zenoh router listening" in log.read_text(), 60.0, "the router", 0.2)
    return log


@pytest.fixture(scope="module")
def router_log(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[Deployment, Path]]:
    tmp = tmp_path_factory.mktemp("tlsr")
    dep = issue(tmp)
    with NodeProcs(Network(0), log_dir=tmp) as procs:
        yield dep, start_router(procs, tmp)


def refused(log: Path, identity: str) -> set[tuple[str, str]]:
    """(action, key) of the refusals the router logged for ``identity``."""
    pattern = rf"access control refused (.+?) on (\S+) from {re.escape(identity)}\b"
    return set(re.findall(pattern, log.read_text()))


@pytest.mark.parametrize("who", ROLE_SENDERS)
def test_each_forged_put_and_token_is_dropped_and_logged_with_its_key_and_identity(
    router_log: tuple[Deployment, Path], who: str
) -> None:
    dep, log = router_log
    host, role, node = sender(who)
    identity = f"{node or role}.{host}"
    forge(dep, who)  # dropped, as test_tls_acl_commands.py checks
    allowed = PRODUCES.get(who, set())
    expected = {("put", k) for k in FORGED if k not in allowed}
    expected |= {("liveliness token", k) for k in TOKENS if k != OWN_TOKEN.get(who)}
    wait_until(
        lambda: expected <= refused(log, identity), 10.0, f"the router's lines for {identity}"
    )
    got = refused(log, identity)
    assert not {(a, k) for a, k in got if k in allowed or k == OWN_TOKEN.get(who)}, got


def test_a_certificate_of_our_ca_that_names_no_identity_is_logged_by_its_zenoh_id(
    router_log: tuple[Deployment, Path],
) -> None:
    dep, log = router_log
    tmp = log.parent
    tls = stranger_tls(tmp / "certs", tmp / "strangers", "stranger.gcs")
    net = NetworkConfig(mode="client", connect=[dep.router], listen=[], tls=tls)
    with open_session(net) as stranger:
        zid = str(stranger.info.zid())
        stranger.put(KEYS.vehicle_status("uav1"), b"forged")
        line = f"access control: zenoh id {zid} shows a certificate that names no identity"
        wait_until(lambda: line in log.read_text(), 10.0, "the router's line for the stranger")


def _listening_ports(pid: int) -> list[int]:
    return [
        c.laddr.port
        for c in psutil.Process(pid).net_connections(kind="tcp")
        if c.status == psutil.CONN_LISTEN
    ]


def _ready_and_listening(log: Path, role: str, pid: int) -> list[int]:
    """Once the node says it is ready: the TCP ports it listens on."""
    wait_until(lambda: f"{role} ready" in log.read_text(), 60.0, f"{role} ready", 0.2)
    return list(wait_until(lambda: _listening_ports(pid), 10.0, f"{role} listening"))


def test_nodes_given_a_hosts_file_listen_on_its_tls_endpoints_only(
    router_log: tuple[Deployment, Path], tmp_path: Path
) -> None:
    """``node ROLE --hosts … --host …`` without ``--listen`` listens where the hosts file says
    (``tls/``), as the nodes of ``up`` do: a plain TCP client opens no session on any port
    it listens on, and two peers of one host, which link to each other, see no link without a
    certificate (one the ACL would refuse wholesale, logged as a certificate that names no
    identity)."""
    _, log = router_log
    hosts = str(log.parent / "hosts.toml")
    roles = ("plume", "physics")
    with NodeProcs(Network(0), log_dir=tmp_path) as procs:
        pids = {
            role: procs.start_module(
                "plumeswarm", "-v", "node", role, "--hosts", hosts, "--host", "sim", label=role
            ).pid
            for role in roles
        }
        ports = {role: _ready_and_listening(tmp_path / f"{role}.log", role, pid)
                 for role, pid in pids.items()}  # fmt: skip
        for role, listening in ports.items():
            for port in listening:
                plain = NetworkConfig(mode="client", connect=[f"tcp/127.0.0.1:{port}"], listen=[])
                assert join_error(plain, None) is not None, f"{role} takes plain TCP on {port}"
        time.sleep(2.0)  # the peers' own link (gossip) is up within a second of both starting
        logs = {role: (tmp_path / f"{role}.log").read_text() for role in roles}
    for role, text in logs.items():
        assert "names no identity" not in text, (role, text[-2000:])
