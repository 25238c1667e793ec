"""``plumeswarm up`` with the real roles: status sees the world, the viewer shows the flight,
``demo --attach`` flies it, and SIGTERM leaves no process behind."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import psutil

from deploy.busview import BusView
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.support.procs import REPO, keys_for, run_cli, wait_until


def _env() -> dict[str, str]:
    return dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")


def test_up_status_viewer_and_clean_stop(tmp_path: Path) -> None:
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    roles = ["router", "plume", "physics", "autopilot", "gateway", "viewer"]
    run = tmp_path / "run"
    with open(tmp_path / "console.txt", "wb") as console:
        up = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "plumeswarm",
                "up",
                "--roles",
                ",".join(roles),
                "--connect",
                endpoint,
                "--out",
                str(run),
            ],
            cwd=REPO,
            env=_env(),
            stdout=console,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
    demo: subprocess.Popen[bytes] | None = None
    try:
        wait_until(
            lambda: up.poll() is None and (run / "pids.json").exists(), 120.0, "up to be ready"
        )
        pids = json.loads((run / "pids.json").read_text())
        family = [psutil.Process(up.pid), *psutil.Process(up.pid).children(recursive=True)]
        assert {"router", "physics", "plume", "viewer", "autopilot-uav2"} <= set(pids)

        result = run_cli(["status", "--json", "--connect", endpoint, "--timeout", "20"])
        assert result.returncode == 0, result.stderr
        status = json.loads(result.stdout)
        nodes = {n["name"]: n for n in status["nodes"]}
        assert nodes["physics"]["pid"] == pids["physics"]
        assert status["sim_time"] is not None and status["real_time_factor"] is not None
        assert sorted(status["vehicles"]) == ["uav1", "uav2", "uav3"]
        assert all(v["position"] is not None for v in status["vehicles"].values())

        with open_session(NetworkConfig(connect=[endpoint], listen=[])) as session:
            view = BusView(session, keys_for())
            demo = subprocess.Popen(
                [
                    sys.executable,
                    "-m",
                    "plumeswarm",
                    "demo",
                    "--attach",
                    endpoint,
                    "--out",
                    str(tmp_path / "demo"),
                    "--timeout",
                    "600",
                ],
                cwd=REPO,
                env=_env(),
                stdout=subprocess.DEVNULL,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
            wait_until(
                lambda: (
                    sum(
                        1
                        for v in view.snapshot().vehicles.values()
                        if v.position is not None and v.position[2] > 8.0
                    )
                    == 3
                ),
                300.0,
                "all three vehicles in the air",
            )
            health = view.snapshot().health["viewer"]
            url = health.detail.split()[0].removeprefix("url=")
            assert url.startswith("http://127.0.0.1:")
            if os.environ.get("PLUMESWARM_SAVE_SCREENSHOT") == "1":
                _screenshot(url, tmp_path)  # docs/viewer.png of a real flight
            view.close()
        assert demo.wait(timeout=600) == 0, "demo --attach did not complete the missions"
        summary = json.loads((tmp_path / "demo" / "summary.json").read_text())
        assert summary["ok"]

        # on-failure restart: a killed autopilot comes back under a new PID and rejoins the bus
        os.killpg(pids["autopilot-uav1"], signal.SIGKILL)

        def restarted() -> int | None:
            new = json.loads((run / "pids.json").read_text()).get("autopilot-uav1")
            return new if new not in (None, pids["autopilot-uav1"]) else None

        new_pid = wait_until(restarted, 60.0, "autopilot-uav1 to be restarted")
        family.append(psutil.Process(new_pid))
        with open_session(NetworkConfig(connect=[endpoint], listen=[])) as session:
            view = BusView(session, keys_for())
            wait_until(
                lambda: (
                    (h := view.snapshot().health.get("autopilot-uav1")) is not None
                    and h.pid == new_pid
                    and "autopilot-uav1" in view.presence.alive
                ),
                120.0,
                "the restarted autopilot-uav1 back on the bus",
            )
            view.close()

        up.send_signal(signal.SIGTERM)
        assert up.wait(timeout=60) == 0
        _, alive = psutil.wait_procs(family, timeout=10.0)
        assert alive == [], f"orphans: {alive}"
        assert "stopped" in (tmp_path / "console.txt").read_text()
    finally:
        for proc in (demo, up):
            if proc is not None and proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(10)


def _screenshot(url: str, tmp_path: Path) -> None:
    """The browser test proper is test_viewer_browser; this only refreshes the picture."""
    chromium = shutil.which("chromium")
    assert chromium is not None, "PLUMESWARM_SAVE_SCREENSHOT=1 needs Debian's chromium"
    import matplotlib.image

    from tests.support.browser import CHROME_FLAGS

    shot = tmp_path / "flight.png"
    subprocess.run(
        [
            chromium,
            *CHROME_FLAGS,
            f"--user-data-dir={tmp_path / 'chrome'}",
            f"--screenshot={shot}",
            "--window-size=1280,800",
            "--virtual-time-budget=6000",
            url,
        ],
        capture_output=True,
        timeout=180,
        check=True,
    )
    img = matplotlib.image.imread(shot)[:, :, :3]
    assert len(np.unique((img * 255).astype(np.uint8).reshape(-1, 3), axis=0)) > 500
    shutil.copy(shot, REPO / "docs" / "viewer.png")
