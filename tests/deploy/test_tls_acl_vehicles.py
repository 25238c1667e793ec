"""Per-vehicle autopilot identities (``[acl] per_vehicle``), on loopback like test_tls_acl.py:
``plumeswarm certs generate`` issues ``autopilot-<vehicle>.<host>``, and the router drops what
such an identity publishes or answers for another vehicle (mTLS + ACL); a forged sample and
then a marker on a key it may use prove it without waiting for a silence."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from functools import partial
from pathlib import Path

import pytest
import zenoh

from deploy.certs import common_name_of
from deploy.hosts import Deployment, HostsError, load_deployment
from deploy.security import secure_network
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import CommandReply, GetParams, VehicleStatus
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.support.procs import REPO, run_cli, wait_until
from tests.support.tls_probe import forged_puts_seen

KEYS = Keys("default")


def write_hosts(path: Path, router: str, per_vehicle: bool = True, vehicles: bool = True) -> Path:
    lines = [f'router = "{router}"', "", "[tls]", 'certs = "certs"', ""]
    if per_vehicle:
        lines += ["[acl]", "per_vehicle = true", ""]
    hosts = {"sim": ["router", "physics", "plume"], "agents": ["autopilot"], "gcs": ["gateway"]}
    for host, roles in hosts.items():
        lines += ["[[hosts]]", f'name = "{host}"', 'address = "127.0.0.1"']
        lines += ["roles = [" + ", ".join(f'"{r}"' for r in roles) + "]"]
        if host == "agents" and vehicles:
            lines += ['vehicles = ["uav1", "uav2"]']
        lines += ['listen = ["tls/127.0.0.1:0"]', ""]
    path.write_text("\n".join(lines))
    return path


@pytest.fixture(scope="module")
def deployment(tmp_path_factory: pytest.TempPathFactory) -> tuple[Deployment, Path]:
    tmp = tmp_path_factory.mktemp("tlsv")
    hosts_file = write_hosts(tmp / "hosts.toml", f"tls/127.0.0.1:{free_tcp_port()}")
    res = run_cli(["certs", "generate", "--hosts", str(hosts_file)])
    assert res.returncode == 0, res.stderr
    return load_deployment(hosts_file), tmp


def client(dep: Deployment, host: str, role: str, node: str | None = None) -> NetworkConfig:
    base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
    return secure_network(base, dep, host, role, KEYS, node)


def _reply_with(text: str, query: zenoh.Query) -> None:
    query.reply(query.key_expr, text)


def test_one_certificate_per_vehicle_and_none_for_any_vehicle(
    deployment: tuple[Deployment, Path],
) -> None:
    _, tmp = deployment
    agents = tmp / "certs" / "agents"
    assert common_name_of(agents / "autopilot-uav1.agents.pem") == "autopilot-uav1.agents"
    assert common_name_of(agents / "autopilot-uav2.agents.pem") == "autopilot-uav2.agents"
    assert not (agents / "autopilot.agents.pem").exists()  # no identity for every vehicle


def test_router_drops_what_an_autopilot_publishes_or_answers_for_another_vehicle(
    deployment: tuple[Deployment, Path],
) -> None:
    dep, _ = deployment
    router = NetworkConfig(mode="router", connect=[], listen=[dep.router])
    with open_session(secure_network(router, dep, "sim", "router", KEYS)):
        listener = client(dep, "sim", "physics")
        uav2 = client(dep, "agents", "autopilot", "autopilot-uav2")
        forged = [
            KEYS.vehicle_actuators("uav1"),
            KEYS.autopilot_actuators("autopilot-uav1"),
            KEYS.vehicle_status("uav1"),
            KEYS.vehicle_state("uav2"),
            KEYS.tick(),
            KEYS.vehicle_actuators("uav2"),  # its own: the control that the probe sees
        ]
        result = forged_puts_seen(
            listener, uav2, KEYS, forged_keys=forged, marker_key=KEYS.vehicle_status("uav2")
        )
        assert result["marker"], "the marker on its own status never arrived: nothing tested"
        assert result["seen"] == [KEYS.vehicle_actuators("uav2")], result

        # Commands: it may serve its own vehicle's, not another's.
        with open_session(uav2) as ap, open_session(client(dep, "gcs", "operator")) as op:
            served = [
                ap.declare_queryable(KEYS.vehicle_cmd(v), partial(_reply_with, v))
                for v in ("uav1", "uav2")
            ]

            def answers(vid: str) -> list[bytes]:
                replies = op.get(KEYS.vehicle_cmd(vid), timeout=2.0)
                return [r.ok.payload.to_bytes() for r in replies if r.ok is not None]

            wait_until(lambda: answers("uav2") == [b"uav2"], 30.0, "uav2's own commands served")
            assert answers("uav1") == []
            for q in served:
                q.undeclare()


def test_a_per_vehicle_autopilot_may_not_take_another_vehicles_presence(
    deployment: tuple[Deployment, Path],
) -> None:
    dep, _ = deployment
    router = NetworkConfig(mode="router", connect=[], listen=[dep.router])
    with (
        open_session(secure_network(router, dep, "sim", "router", KEYS)),
        open_session(client(dep, "agents", "autopilot", "autopilot-uav2")) as ap,
        open_session(client(dep, "sim", "physics")) as physics,
    ):
        tokens = [
            ap.liveliness().declare_token(KEYS.node_health(n))
            for n in ("autopilot-uav2", "autopilot-uav1")
        ]

        def seen() -> list[str]:
            replies = physics.liveliness().get(KEYS.all_node_health(), timeout=2.0)
            return sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)

        wait_until(lambda: KEYS.node_health("autopilot-uav2") in seen(), 30.0, "its own token")
        assert KEYS.node_health("autopilot-uav1") not in seen()
        for t in tokens:
            t.undeclare()


def test_per_vehicle_identities_need_one_vehicle_per_process_and_the_hosts_vehicles(
    deployment: tuple[Deployment, Path], tmp_path: Path
) -> None:
    dep, _ = deployment
    with pytest.raises(HostsError, match="one vehicle per process"):
        client(dep, "agents", "autopilot", "autopilot-uav1-plus1")
    with pytest.raises(HostsError, match=r"vehicles = \[...\]"):
        load_deployment(write_hosts(tmp_path / "h.toml", "tls/127.0.0.1:7447", vehicles=False))


def test_a_real_autopilot_process_serves_its_vehicle_under_its_own_identity(
    deployment: tuple[Deployment, Path], tmp_path: Path
) -> None:
    """``plumeswarm node autopilot --vehicle uav1 --hosts … --host agents`` runs as
    ``autopilot-uav1.agents``: its token, its status and its answers reach an operator, so the
    allow-list covers what an autopilot does."""
    dep, tmp = deployment
    router = NetworkConfig(mode="router", connect=[], listen=[dep.router])
    cmd = [
        sys.executable,
        "-m",
        "deploy",
        "node",
        "autopilot",
        "--vehicle",
        "uav1",
        "--hosts",
        str(tmp / "hosts.toml"),
        "--host",
        "agents",
        "--listen",
        "tls/127.0.0.1:0",
    ]
    statuses: list[VehicleStatus] = []
    with (
        open_session(secure_network(router, dep, "sim", "router", KEYS)),
        open_session(client(dep, "gcs", "operator")) as op,
        open(tmp_path / "autopilot.log", "wb") as log,
    ):
        sub = op.declare_subscriber(
            KEYS.vehicle_status("uav1"),
            lambda s: statuses.append(decode(s.payload.to_bytes(), VehicleStatus)),
        )
        proc = subprocess.Popen(
            cmd, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), start_new_session=True,
            stdout=log, stderr=subprocess.STDOUT,
        )  # fmt: skip
        try:
            wait_until(
                lambda: (
                    KEYS.node_health("autopilot-uav1")
                    in [
                        str(r.ok.key_expr)
                        for r in op.liveliness().get(KEYS.all_node_health(), timeout=2.0)
                        if r.ok is not None
                    ]
                ),
                90.0,
                "the autopilot's token",
                poll_s=0.5,
            )
            wait_until(lambda: statuses, 30.0, "its status")
            replies = [
                decode(r.ok.payload.to_bytes(), CommandReply)
                for r in op.get(KEYS.vehicle_cmd("uav1"), payload=encode(GetParams()), timeout=10.0)
                if r.ok is not None
            ]
            assert replies and replies[0].accepted and replies[0].params, replies
        finally:
            sub.undeclare()
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(30)
    assert statuses[0].vehicle_id == "uav1"
