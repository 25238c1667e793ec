"""``plumeswarm up`` as a real process: readiness, pids.json, ordered stop, no orphans."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import msgspec
import psutil
import pytest

from deploy.scaling import scale_scenario, write_scenario
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, Presence, free_tcp_port, free_udp_block, open_session
from tests.support.procs import keys_for, wait_until
from tests.support.upstack import spawn_up


def family_of(pid: int) -> list[psutil.Process]:
    root = psutil.Process(pid)
    return [root, *root.children(recursive=True)]


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_up_writes_pids_and_stops_everything_on_signal(tmp_path: Path, sig: int) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    up = spawn_up(["--roles", "router", "--connect", endpoint], tmp_path)
    try:
        pids_file = tmp_path / "run" / "pids.json"
        wait_until(pids_file.exists, 60.0, "pids.json")
        pids = json.loads(pids_file.read_text())
        assert set(pids) == {"router"}
        family = family_of(up.pid)
        assert pids["router"] in {p.pid for p in family}
        # The router it started is really on the bus.
        with open_session(NetworkConfig(connect=[endpoint], listen=[])) as session:
            presence = Presence(session, keys_for())
            assert presence.wait_for(lambda a: "router" in a, 20.0), sorted(presence.alive)
            presence.close()
        os.kill(up.pid, sig)
        up.wait(timeout=30)
        out = (tmp_path / "console.txt").read_text()
        assert up.returncode == 0, out
        assert "stopped" in out
        _, alive = psutil.wait_procs(family, timeout=5.0)
        assert alive == [], f"orphans: {alive}"
        assert "router ready" in (tmp_path / "run" / "router.log").read_text()
    finally:
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGKILL)
            up.wait(10)


def test_killed_launcher_takes_its_children_along(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    up = spawn_up(["--roles", "router", "--connect", endpoint], tmp_path)
    try:
        wait_until((tmp_path / "run" / "pids.json").exists, 60.0, "pids.json")
        family = family_of(up.pid)
        up.kill()  # SIGKILL: no chance to clean up; the parent-death signal does it
        up.wait(10)
        _, alive = psutil.wait_procs(family[1:], timeout=15.0)
        assert alive == [], f"orphans: {alive}"
    finally:
        if up.poll() is None:
            up.kill()
            up.wait(10)


def test_a_role_whose_package_is_missing_fails_before_anything_starts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from deploy import launcher, roles
    from swarmbus.scenario import load_scenario
    from tests.support.procs import NODE_COMMAND

    monkeypatch.setitem(roles.ROLES, "plume", "no_such_package.service:main")
    opts = launcher.LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=Path("novak2018.toml"),
        roles=("router", "plume"),
        run_dir=tmp_path,
    )
    with pytest.raises(launcher.LaunchError) as info:
        launcher.Launcher(load_scenario(), opts).start()
    message = str(info.value)
    assert "\n" not in message and "plume (no_such_package.service)" in message
    assert list(tmp_path.iterdir()) == [], "nothing was started"


def test_up_says_once_which_vehicles_are_not_on_mavlink(tmp_path: Path) -> None:
    base = scale_scenario(load_scenario(), 256)
    gateway = msgspec.structs.replace(
        base.gateway, gcs_port=free_udp_block(1), api_port_base=free_udp_block(254)
    )
    scenario = write_scenario(
        msgspec.structs.replace(base, gateway=gateway), tmp_path / "s256.toml"
    )
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    up = spawn_up([str(scenario), "--roles", "router,gateway", "--connect", endpoint], tmp_path)
    console = tmp_path / "console.txt"
    try:
        wait_until(lambda: "processes ready" in console.read_text(), 120.0, "up ready")
        os.kill(up.pid, signal.SIGTERM)
        up.wait(timeout=30)
        out = console.read_text()
        note = "2 vehicle(s) not on MAVLink: MAVLink addresses systems 1–254"
        assert out.count(f"plumeswarm: {note}") == 1, out
        assert (tmp_path / "run" / "gateway.log").read_text().count(note) == 1
    finally:
        if up.poll() is None:
            os.killpg(up.pid, signal.SIGKILL)
            up.wait(10)
