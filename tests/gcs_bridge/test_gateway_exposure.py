"""Who can reach the MAVLink links: a bind address per link (the GCS link apart from the API
links), ``plumeswarm up`` refusing unsigned links beyond loopback unless ``--insecure``, and a
force disarm sent to every system (target_system 0) logged and, with the option, refused.

Real gateway, fake autopilots on a real bus; nothing binds beyond loopback (the second
loopback address 127.0.0.2 stands for the GCS link's own address)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from gcs_bridge.dialect import mavlink
from gcs_bridge.options import GatewayOptions, unsigned_exposed
from swarmbus.scenario import GatewaySpec
from swarmbus.session import free_tcp_port
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, write_scenario
from tests.support.procs import REPO, run_cli, wait_until, zenoh_network

REMOTE = ("--set", "gateway.host=192.0.2.7")  # a ground station on another machine
ARM = 400
FORCE = 21196


def test_up_refuses_unsigned_links_beyond_loopback(tmp_path: Path) -> None:
    res = run_cli(["up", "novak2018", *REMOTE, "--out", str(tmp_path / "a")])
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert res.returncode == 2 and len(lines) == 1, res.stderr
    assert "gcs link on 0.0.0.0, api link on 0.0.0.0" in lines[0] and "--insecure" in lines[0]
    api_local = [*REMOTE, "--set", "gateway.api_host=127.0.0.1"]
    res = run_cli(["up", "novak2018", *api_local, "--out", str(tmp_path / "b")])
    assert res.returncode == 2 and "(gcs link on 0.0.0.0)" in res.stderr, res.stderr


def test_signed_or_loopback_links_are_not_exposed() -> None:
    key = "ab" * 32
    signed = GatewaySpec(host="192.0.2.7", signing_key_hex=key)
    assert unsigned_exposed(signed, GatewayOptions()) == []
    gcs_only = GatewayOptions(signed_links="gcs")
    assert unsigned_exposed(signed, gcs_only) == ["api link on 0.0.0.0"]
    assert (
        unsigned_exposed(
            GatewaySpec(host="192.0.2.7", api_host="127.0.0.1", signing_key_hex=key), gcs_only
        )
        == []
    )
    assert unsigned_exposed(GatewaySpec(), GatewayOptions()) == []


def test_up_insecure_warns_in_one_line(tmp_path: Path) -> None:
    """With ``--insecure`` it goes on (here: waits for a router that is not there, so the
    gateway never binds) after one warning line."""
    router = f"tcp/127.0.0.1:{free_tcp_port()}"
    cmd = [sys.executable, "-m", "plumeswarm", "up", "novak2018", "--insecure", *REMOTE,
           "--set", "gateway.api_host=127.0.0.1", "--roles", "gateway", "--no-router",
           "--connect", router, "--out", str(tmp_path / "run")]  # fmt: skip
    err = tmp_path / "stderr"
    with open(err, "wb") as f:
        proc = subprocess.Popen(cmd, cwd=REPO, stderr=f, stdout=subprocess.DEVNULL,
                                env=dict(os.environ, PYTHONPATH=str(REPO)),
                                start_new_session=True)  # fmt: skip
    try:
        wait_until(lambda: "warning" in err.read_text(), 60.0, "the warning", poll_s=0.2)
        time.sleep(0.5)
        assert proc.poll() is None, err.read_text()  # not refused
    finally:  # it started nothing yet: no need to stop it in order
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(30)
    warnings = [ln for ln in err.read_text().splitlines() if "warning" in ln]
    assert len(warnings) == 1 and "(gcs link on 0.0.0.0)" in warnings[0], err.read_text()


def broadcast_force_disarm(client: MavClient) -> None:
    msg = mavlink.MAVLink_command_long_message(0, 0, ARM, 0, 0, FORCE, 0, 0, 0, 0, 0)
    client.send(1, msg)


def arm_both(gcs: MavClient) -> None:
    for sysid in (1, 2):
        gcs.wait_standby(sysid)
        assert gcs.command(sysid, ARM, 1) == mavlink.MAV_RESULT_ACCEPTED
        gcs.wait_armed(sysid)


def test_links_bind_apart_and_a_broadcast_force_disarm_is_refused_on_request(
    tmp_path: Path,
) -> None:
    scenario, gcs_port, api_base = write_scenario(tmp_path / "scenario.toml", 2)
    log = tmp_path / "gateway.log"
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1", "uav2"]),
        gateway(
            net, scenario, tmp_path, "gcs_bind_host=127.0.0.2", "refuse_broadcast_disarm=true"
        ),  # fmt: skip
        MavClient(gcs_port) as gcs,
        MavClient(api_base) as api,
    ):
        arm_both(gcs)
        api.wait_type("HEARTBEAT", 1)
        assert gcs.addr_of[1][0] == "127.0.0.2" and api.addr_of[1][0] == "127.0.0.1"
        gcs.drain()
        broadcast_force_disarm(gcs)
        for sysid in (1, 2):
            ack = gcs.wait_type("COMMAND_ACK", sysid, 30.0, command=ARM)
            assert ack.result == mavlink.MAV_RESULT_DENIED
        gcs.drain()
        for sysid in (1, 2):  # a heartbeat sent after the refusal: still armed
            hb = gcs.wait_type("HEARTBEAT", sysid)
            assert hb.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
    text = log.read_text()
    assert text.count("force disarm to every system (target_system 0)") == 2, text
    assert "refused (refuse_broadcast_disarm)" in text


def test_a_broadcast_force_disarm_is_logged_and_by_default_obeyed(tmp_path: Path) -> None:
    scenario, gcs_port, _ = write_scenario(tmp_path / "scenario.toml", 2)
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1", "uav2"]),
        gateway(net, scenario, tmp_path),
        MavClient(gcs_port) as gcs,
    ):
        arm_both(gcs)
        broadcast_force_disarm(gcs)
        for sysid in (1, 2):
            gcs.wait_armed(sysid, armed=False, timeout_s=30.0)
    text = (tmp_path / "gateway.log").read_text()
    assert text.count("force disarm to every system (target_system 0)") == 2, text
