"""Zenoh over mutual TLS with the deployment's access-control list, on loopback (no root).

A hosts file with ``[tls]`` and three hosts on 127.0.0.1, certificates from ``plumeswarm certs
generate``, and in-process sessions built with the very functions the CLI uses
(:func:`deploy.security.secure_network`): the router enforces the ACL on its links, and a peer
enforces it on a direct link. The namespace test (``test_netns_tls.py``) does the same across
hosts with the real processes flying.
"""

from __future__ import annotations

import itertools
import re
import shutil
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import msgspec
import pytest
import zenoh
from cryptography import x509

from deploy import certs
from deploy.certs import common_name_of
from deploy.hosts import Deployment, HostsError, load_deployment
from deploy.security import ROLE_PLANES, access_control, host_identities, secure_network
from swarmbus.keys import Keys
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.deploy.test_faults_cli import assert_one_clear_line, bad_file
from tests.support.hosts import write_hosts
from tests.support.mavclient import write_scenario
from tests.support.procs import REPO, run_cli
from tests.support.tls_probe import (
    door,
    forbidden_keys,
    forged_puts_seen,
    join_error,
    marker_of,
    stranger_tls,
)

KEYS = Keys("default")


def generate(hosts_file: Path, *extra: str) -> None:
    res = run_cli(["certs", "generate", "--hosts", str(hosts_file), *extra])
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="module")
def certified(tmp_path_factory: pytest.TempPathFactory) -> tuple[Deployment, Path]:
    """A loopback hosts file with its certificates (by the CLI) and another CA's."""
    tmp = tmp_path_factory.mktemp("tls")
    router = f"tls/127.0.0.1:{free_tcp_port()}"
    hosts_file = write_hosts(tmp / "hosts.toml", router, tls_certs="certs")
    generate(hosts_file)
    dep = load_deployment(hosts_file)
    certs.generate(host_identities(dep), tmp / "other-ca", days=1)
    return dep, tmp


@pytest.fixture(scope="module")
def deployment(certified: tuple[Deployment, Path]) -> Iterator[tuple[Deployment, Path]]:
    """``certified`` with a running router enforcing the ACL."""
    dep, tmp = certified
    router = dep.router
    net = NetworkConfig(mode="router", connect=[], listen=[router])
    with open_session(secure_network(net, dep, "sim", "router", KEYS)):
        yield dep, tmp


def as_role(dep: Deployment, host: str, role: str, **changes: object) -> NetworkConfig:
    """A client session of ``role`` on ``host`` (a peer that listens on nothing would reach
    nobody: a zenoh 1.10 router does not route between peers)."""
    base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
    return msgspec.structs.replace(secure_network(base, dep, host, role, KEYS), **changes)


def test_generated_certificates_carry_the_identities(certified: tuple[Deployment, Path]) -> None:
    _, tmp = certified
    out = tmp / "certs"
    assert common_name_of(out / "agents" / "autopilot.agents.pem") == "autopilot.agents"
    assert common_name_of(out / "gcs" / "operator.gcs.pem") == "operator.gcs"
    assert (out / "sim" / "physics.sim.key").stat().st_mode & 0o077 == 0
    again = run_cli(["certs", "generate", "--hosts", str(tmp / "hosts.toml")])
    assert again.returncode != 0 and "refusing to replace" in again.stderr


def allows(acl: dict[str, Any], name: str, message: str, key: str) -> bool:
    """Whether ``acl`` lets identity ``name`` send ``message`` on ``key`` (ingress), decided
    by zenoh's own key algebra: some allow rule of its policies includes the key."""
    subjects = {s["id"] for s in acl["subjects"] if name in s["cert_common_names"]}
    ids = {r for p in acl["policies"] if subjects & set(p["subjects"]) for r in p["rules"]}
    return any(
        zenoh.KeyExpr(k).includes(zenoh.KeyExpr(key))
        for r in acl["rules"]
        if r["id"] in ids and r["permission"] == "allow" and "ingress" in r["flows"]
        and message in r["messages"]
        for k in r["key_exprs"]
    )  # fmt: skip


def test_acl_names_who_may_send_what(tmp_path: Path) -> None:
    hosts_file = write_hosts(
        tmp_path / "hosts.toml", "tls/10.0.0.1:7447", addresses="10.0.0.1", tls_certs="c"
    )
    acl = access_control(load_deployment(hosts_file), KEYS)
    assert acl["default_permission"] == "deny"
    names = ["router.sim", "physics.sim", "plume.sim", "autopilot.agents", "gateway.gcs",
             "operator.gcs"]  # fmt: skip
    expected = [
        ("put", KEYS.autopilot_actuators("autopilot-uav1"), {"router.sim", "autopilot.agents"}),
        ("put", KEYS.tick(), {"router.sim", "physics.sim"}),
        ("put", KEYS.vehicle_state("uav1"), {"router.sim", "physics.sim"}),
        ("put", KEYS.plume_sample(), {"router.sim", "plume.sim"}),
        ("put", KEYS.vehicle_status("uav1"), {"router.sim", "autopilot.agents"}),
        ("put", KEYS.node_restart("physics"), {"router.sim", "operator.gcs"}),
        ("put", KEYS.everything(), {"router.sim"}),
        ("query", KEYS.vehicle_cmd("uav1"), {"router.sim", "autopilot.agents", "gateway.gcs",
                                             "operator.gcs"}),
        ("query", KEYS.everything(), {"router.sim"}),
        ("query", KEYS.clock_step(), {"router.sim", "gateway.gcs", "operator.gcs"}),
        ("declare_queryable", KEYS.vehicle_cmd("uav1"), {"router.sim", "autopilot.agents"}),
        ("liveliness_token", KEYS.node_health("physics"), {"router.sim", "physics.sim"}),
        ("liveliness_token", KEYS.node_health("gateway"), {"router.sim", "gateway.gcs"}),
    ]  # fmt: skip
    for message, key, who in expected:
        assert {n for n in names if allows(acl, n, message, key)} == who, (message, key)
    inside_router = access_control(load_deployment(hosts_file), KEYS, "router")
    assert not allows(inside_router, "router.sim", "put", KEYS.tick())


@pytest.mark.parametrize(
    ("publisher", "allowed"),
    [
        (("agents", "autopilot"), {"actuators"}),
        (("sim", "physics"), {"state", "tick"}),
        (("gcs", "gateway"), set()),
        (("gcs", "operator"), set()),
        (("sim", "plume"), set()),
    ],
)
def test_router_lets_only_the_right_role_publish(
    deployment: tuple[Deployment, Path], publisher: tuple[str, str], allowed: set[str]
) -> None:
    dep, _ = deployment
    listener = as_role(dep, "sim", "physics")  # the real subscriber of actuators
    marker = marker_of(dep, *publisher, KEYS)
    result = forged_puts_seen(listener, as_role(dep, *publisher), KEYS, marker_key=marker)
    assert result["marker"], "the publisher's marker never arrived: nothing was tested"
    leaf = {k: k.rsplit("/", 1)[-1] for k in forbidden_keys(KEYS)}
    assert {leaf[k] for k in result["seen"]} == allowed


def test_a_peer_enforces_the_acl_on_a_direct_link(deployment: tuple[Deployment, Path]) -> None:
    """A gateway that connects straight to physics's listener (no router between) is refused
    there too; an autopilot on the same kind of link is not."""
    dep, _ = deployment
    physics_ep = f"tls/127.0.0.1:{free_tcp_port()}"
    physics = as_role(dep, "sim", "physics", mode="peer", connect=[], listen=[physics_ep])
    for host, role, allowed in (("gcs", "gateway", 0), ("agents", "autopilot", 1)):
        direct = as_role(dep, host, role, connect=[physics_ep])
        result = forged_puts_seen(
            physics, direct, KEYS, marker_key=marker_of(dep, host, role, KEYS)
        )
        assert result["marker"]
        assert len(result["seen"]) == allowed, (role, result)


def test_strangers_cannot_join(deployment: tuple[Deployment, Path]) -> None:
    dep, tmp = deployment
    stranger = stranger_tls(tmp / "certs", tmp / "strangers", "stranger.gcs")
    with open_session(as_role(dep, "sim", "plume")) as s:
        token = s.liveliness().declare_token(KEYS.node_health("plume"))
        result = door(dep, "gcs", KEYS, tmp / "other-ca", stranger)
        token.undeclare()
    assert result["operator_tokens"] == [KEYS.node_health("plume")]
    assert result["operator"] is None, f"our own operator could not join: {result['operator']}"
    assert result["no_cert"] is not None, "a client without a certificate joined"
    assert result["other_ca"] is not None, "a client with another CA's certificate joined"
    assert result["plain_tcp"] is not None, "a plain TCP client joined"
    # A certificate of our CA with an unknown name connects but is shown nothing.
    assert result["stranger_tokens"] == []


@pytest.mark.parametrize(
    ("which", "kind"), [("root_ca", "missing"), ("cert", "directory"), ("key", "not-pem")]
)
def test_bad_tls_files_are_one_clear_line(
    certified: tuple[Deployment, Path], tmp_path: Path, which: str, kind: str
) -> None:
    _, tmp = certified
    shutil.copytree(tmp / "certs", tmp_path / "certs")
    hosts_file = tmp_path / "hosts.toml"
    shutil.copy(tmp / "hosts.toml", hosts_file)
    files = {
        "root_ca": tmp_path / "certs" / "ca.pem",
        "cert": tmp_path / "certs" / "agents" / "autopilot.agents.pem",
        "key": tmp_path / "certs" / "agents" / "autopilot.agents.key",
    }
    bad = files[which]
    bad.unlink()
    if kind == "directory":
        bad.mkdir()
    elif kind == "not-pem":
        bad.write_bytes(b"\x00garbage")
    res = run_cli(
        ["node", "autopilot", "--vehicle", "uav1", "--hosts", str(hosts_file), "--host", "agents"]
    )
    assert res.returncode != 0
    assert "Traceback" not in res.stderr, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and str(bad) in lines[0], res.stderr


@pytest.mark.parametrize(
    ("router", "listen", "tls", "error"),
    [
        ("tcp/10.0.0.1:7447", "tls/10.0.0.1:0", True, "every endpoint must be tls/"),
        ("tls/10.0.0.1:7447", "tcp/10.0.0.1:0", True, "every endpoint must be tls/"),
        ("tls/10.0.0.1:7447", "tls/10.0.0.1:0", False, "need a [tls] section"),
    ],
)
def test_tls_endpoints_and_section_go_together(
    tmp_path: Path, router: str, listen: str, tls: bool, error: str
) -> None:
    text = f'router = "{router}"\n' + ('[tls]\ncerts = "c"\n' if tls else "")
    text += f'[[hosts]]\nname = "sim"\nroles = ["router"]\nlisten = ["{listen}"]\n'
    (tmp_path / "hosts.toml").write_text(text)
    with pytest.raises(HostsError, match=re.escape(error)):
        load_deployment(tmp_path / "hosts.toml")


@pytest.mark.parametrize("kind", ["missing", "garbage"])
def test_certs_generate_with_a_bad_hosts_file_is_one_line(tmp_path: Path, kind: str) -> None:
    f = bad_file(tmp_path, kind, ".toml")
    assert_one_clear_line(["certs", "generate", "--hosts", f, "--out", str(tmp_path / "c")])


@pytest.mark.parametrize(
    ("host", "error"),
    [
        ('rols = ["router"]', "hosts[0].rols: unknown key (did you mean 'roles'?); valid: name, "),
        ('roles = ["routr"]', "hosts[0].roles[0]: invalid choice, got 'routr' (did you mean "
         "'router'?); valid: "),
    ],
)  # fmt: skip
def test_a_bad_hosts_file_key_or_role_names_it_and_the_valid_ones(
    tmp_path: Path, host: str, error: str
) -> None:
    (tmp_path / "hosts.toml").write_text(
        f'router = "tcp/127.0.0.1:7447"\n[[hosts]]\nname = "sim"\n{host}\n'
    )
    with pytest.raises(HostsError) as info:
        load_deployment(tmp_path / "hosts.toml")
    assert str(info.value).startswith(f"{tmp_path / 'hosts.toml'}: {error}"), info.value


def test_the_role_table_of_the_docs_is_the_one_the_acl_is_made_from() -> None:
    """docs/deploy.md's table of roles and planes lists every role with the planes of
    :data:`deploy.security.ROLE_PLANES` (the defaults of ``[acl]``)."""
    lines = (REPO / "docs" / "deploy.md").read_text().splitlines()
    start = lines.index("| role | planes | may send (put/delete unless said) |") + 2
    documented: dict[str, tuple[str, ...]] = {}
    for line in itertools.takewhile(lambda ln: ln.startswith("|"), lines[start:]):
        roles, planes, _ = (c.strip() for c in line.strip("|").split("|"))
        named = () if planes == "none" else tuple(p.strip() for p in planes.split(","))
        for role in roles.split("(")[0].split(","):
            documented[role.strip()] = named
    assert documented == ROLE_PLANES


def test_acl_off_keeps_mutual_tls_and_lets_every_identity_send(
    certified: tuple[Deployment, Path],
) -> None:
    """``[acl] enabled = false``: TLS stays on (a client without a certificate, with another
    CA's or over plain TCP still does not get in) and nothing an identity sends is refused (the
    gateway's forged actuators, state and tick all reach the physics)."""
    dep, tmp = certified
    off = msgspec.structs.replace(
        dep,
        router=f"tls/127.0.0.1:{free_tcp_port()}",
        acl=msgspec.structs.replace(dep.acl, enabled=False),
    )
    router = secure_network(
        NetworkConfig(mode="router", connect=[], listen=[off.router]), off, "sim", "router", KEYS
    )
    assert router.tls is not None and router.access_control is None
    with open_session(router), open_session(as_role(off, "sim", "plume")) as plume:
        token = plume.liveliness().declare_token(KEYS.node_health("plume"))  # for door()
        result = forged_puts_seen(
            as_role(off, "sim", "physics"),
            as_role(off, "gcs", "gateway"),
            KEYS,
            marker_key=marker_of(off, "gcs", "gateway", KEYS),
        )
        stranger = stranger_tls(tmp / "certs", tmp / "strangers-acl-off", "stranger.gcs")
        outside = door(off, "gcs", KEYS, tmp / "other-ca", stranger)
        token.undeclare()
    assert result["marker"], "the gateway's marker never arrived: nothing was tested"
    assert sorted(result["seen"]) == sorted(forbidden_keys(KEYS)), result
    assert outside["operator"] is None, outside
    for how in ("no_cert", "other_ca", "plain_tcp"):
        assert outside[how] is not None, f"{how} joined with the ACL off: {outside}"


def test_a_scenarios_network_tls_puts_its_sessions_on_mutual_tls(
    certified: tuple[Deployment, Path], tmp_path: Path
) -> None:
    """Without a hosts file, ``[network.tls]`` of a scenario: every session made from the
    scenario's network shows that one identity; one with it joins a router made from it and
    exchanges samples, one without a certificate or over plain TCP does not join."""
    _, tmp = certified
    issued = certs.Authority.load(tmp / "certs").issue_to(
        tmp_path / "run", "run.local", ["127.0.0.1"], 1
    )
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 1)
    with path.open("a") as f:
        f.write(
            f'\n[network.tls]\nroot_ca = "{tmp / "certs" / "ca.pem"}"\n'
            f'cert = "{issued.cert}"\nkey = "{issued.key}"\n'
        )
    net = load_scenario(path).network
    assert net.tls is not None and common_name_of(Path(net.tls.cert)) == "run.local"
    endpoint = f"tls/127.0.0.1:{free_tcp_port()}"
    router = net.with_overrides(mode="router", connect=[], listen=[endpoint])
    client = net.with_overrides(mode="client", connect=[endpoint], listen=[])
    got = threading.Event()
    with open_session(router), open_session(client) as a, open_session(client) as b:
        sub = b.declare_subscriber("tls/check", lambda _: got.set())
        deadline = time.monotonic() + 10.0
        while not got.is_set() and time.monotonic() < deadline:
            a.put("tls/check", b"x")
            got.wait(0.1)
        sub.undeclare()
        assert got.is_set(), "no sample between two sessions of the scenario's identity"
        bare = NetworkConfig(mode="client", connect=[endpoint], listen=[])
        assert join_error(bare, {"root_ca_certificate": net.tls.root_ca}) is not None
        plain = NetworkConfig(mode="client", connect=[endpoint.replace("tls/", "tcp/")], listen=[])
        assert join_error(plain, None) is not None


def test_certificates_are_valid_from_5_minutes_before_they_were_written(
    certified: tuple[Deployment, Path],
) -> None:
    """docs/reliability.md, "Clocks of the hosts": a host whose clock is up to 5 minutes behind
    the one that made the certificates accepts them (beyond that, TLS refuses them)."""
    _, tmp = certified
    for pem in [tmp / "certs" / "ca.pem", *sorted((tmp / "certs").glob("*/*.pem"))]:
        cert = x509.load_pem_x509_certificate(pem.read_bytes())
        written = pem.stat().st_mtime
        lead_s = written - cert.not_valid_before_utc.timestamp()
        assert 300.0 - 30.0 < lead_s < 300.0 + 30.0, (pem.name, lead_s)
