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
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    CommandReply,
    GetParams,
    SimTick,
    VehicleStatus,
)
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.support import hosts
from tests.support.procs import REPO, run_cli, wait_until
from tests.support.tls_probe import forged_puts_seen

KEYS = Keys("default")


def write_hosts(path: Path, router: str, per_vehicle: bool = True, vehicles: bool = True) -> Path:
    served = {"agents": ["uav1", "uav2"]} if vehicles else None
    return hosts.write_hosts(
        path, router, tls_certs="certs", per_vehicle_acl=per_vehicle, vehicles=served
    )


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
        own = KEYS.autopilot_actuators("autopilot-uav2")  # the control that the probe sees
        forged = [
            KEYS.autopilot_actuators("autopilot-uav1"),
            KEYS.autopilot_actuators("autopilot-uav1-plus1"),
            KEYS.vehicle_status("uav1"),
            KEYS.vehicle_state("uav2"),
            KEYS.tick(),
            own,
        ]
        result = forged_puts_seen(
            listener, uav2, KEYS, forged_keys=forged, marker_key=KEYS.vehicle_status("uav2")
        )
        assert result["marker"], "the marker on its own status never arrived: nothing tested"
        assert result["seen"] == [own], result

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
        "plumeswarm",
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


VEHICLE_X = (("uav1", 0.0), ("uav2", 5.0))
SCENARIO = (
    '[world]\nname = "default"\nseed = 7\n[time]\nparticipant_timeout_s = 120.0\n'
    "startup_timeout_s = 120.0\n"
    + "".join(f'[[vehicles]]\nid = "{v}"\nspawn_enu_m = [{x}, 0.0, 0.0]\n' for v, x in VEHICLE_X)
)


def test_a_vehicle_identity_cannot_answer_for_another_vehicle_in_its_own_batch(
    deployment: tuple[Deployment, Path], tmp_path: Path
) -> None:
    """``autopilot-uav2.agents`` may put on its own batch key; a real physics under mTLS + ACL
    takes only uav2's command from it. uav1's autopilot is present but silent, so a forged
    command for uav1 in uav2's batch is the only thing that could answer tick 0 for it: tick 0
    must stay held (and the drop be logged) until uav1's own identity answers on its own key."""
    dep, tmp = deployment
    scenario = tmp_path / "sc.toml"
    scenario.write_text(SCENARIO)
    router = NetworkConfig(mode="router", connect=[], listen=[dep.router])
    cmd = [
        sys.executable, "-m", "plumeswarm", "node", "physics", "--scenario", str(scenario),
        "--hosts", str(tmp / "hosts.toml"), "--host", "sim", "--listen", "tls/127.0.0.1:0",
    ]  # fmt: skip
    ticks: list[int] = []
    log_path = tmp_path / "physics.log"

    def command(vid: str, tick: int) -> ActuatorCommand:
        return ActuatorCommand(vehicle_id=vid, tick=tick, rotor_commands=[0.0] * 4)

    with (
        open_session(secure_network(router, dep, "sim", "router", KEYS)),
        open_session(client(dep, "gcs", "operator")) as op,
        open_session(client(dep, "agents", "autopilot", "autopilot-uav1")) as uav1,
        open_session(client(dep, "agents", "autopilot", "autopilot-uav2")) as uav2,
        open(log_path, "wb") as log,
    ):
        watch = op.declare_subscriber(
            KEYS.tick(), lambda s: ticks.append(decode(s.payload.to_bytes(), SimTick).tick)
        )
        own_key = KEYS.autopilot_actuators("autopilot-uav2")

        def answer_for_both(sample: zenoh.Sample) -> None:
            k = decode(sample.payload.to_bytes(), SimTick).tick
            batch = ActuatorBatch(tick=k, commands=[command("uav2", k), command("uav1", k)])
            uav2.put(own_key, encode(batch))

        forger = uav2.declare_subscriber(KEYS.tick(), answer_for_both)
        tokens = [
            s.liveliness().declare_token(KEYS.node_health(f"autopilot-{v}"))
            for s, v in ((uav1, "uav1"), (uav2, "uav2"))
        ]
        proc = subprocess.Popen(
            cmd, cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1"),
            start_new_session=True, stdout=log, stderr=subprocess.STDOUT,
        )  # fmt: skip
        try:
            wait_until(
                lambda: (
                    "ignoring actuators for uav1 on" in log_path.read_text()
                    or max(ticks, default=0)
                ),
                120.0,
                "the physics dropping uav1's command from uav2's batch",
                poll_s=0.5,
            )
            assert ticks and max(ticks) == 0, f"uav2's batch answered for uav1: ticks {ticks}"
            assert "ignoring actuators for uav1 on" in log_path.read_text()
            uav1.put(KEYS.autopilot_actuators("autopilot-uav1"), encode(
                ActuatorBatch(tick=0, commands=[command("uav1", 0)])
            ))  # fmt: skip
            wait_until(lambda: max(ticks) >= 1, 30.0, "tick 1 once uav1 answered on its own key")
        finally:
            os.killpg(proc.pid, signal.SIGTERM)
            proc.wait(30)
            for t in tokens:
                t.undeclare()
            forger.undeclare()
            watch.undeclare()
