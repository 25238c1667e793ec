"""MAVProxy (1.8.x, scripted through its console on a pipe) arms, takes off and lands a vehicle.

MAVProxy is connected to vehicle 1's API port (``udpin``, PX4 SITL's 14540 + i convention);
a raw client on the shared GCS port watches the same vehicle climb and disarm.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient, write_scenario
from tests.support.procs import zenoh_network

MAVPROXY = shutil.which("mavproxy.py") or str(Path(sys.executable).parent / "mavproxy.py")
pytestmark = pytest.mark.skipif(not Path(MAVPROXY).exists(), reason="mavproxy not installed")


class Console:
    """MAVProxy's console on a pipe: type a line, wait for a line of output."""

    def __init__(self, args: list[str], cwd: Path) -> None:
        self.proc = subprocess.Popen(
            args,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            cwd=cwd,
            start_new_session=True,
        )
        self.lines: list[str] = []
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for raw in self.proc.stdout:
            with self._cond:
                self.lines.append(raw.decode(errors="replace").rstrip())
                self._cond.notify_all()

    def type(self, line: str) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.write((line + "\n").encode())
        self.proc.stdin.flush()

    def expect(self, text: str, timeout_s: float = 60.0) -> None:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while not any(text in line for line in self.lines):
                left = deadline - time.monotonic()
                if left <= 0:
                    tail = "\n".join(self.lines[-15:])
                    raise AssertionError(f"MAVProxy never printed {text!r}; last lines:\n{tail}")
                self._cond.wait(left)

    def close(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)  # MAVProxy ignores SIGTERM on a pipe
        self.proc.wait(timeout=10)
        self._reader.join(timeout=10)  # the pipe reaches EOF once MAVProxy is gone
        for pipe in (self.proc.stdin, self.proc.stdout):
            if pipe is not None:
                pipe.close()


def mavproxy_console(api_base: int, sysid: int, tmp_path: Path) -> Console:
    """MAVProxy on the vehicle's API port (MAVLink 2), its state files under ``tmp_path``."""
    return Console(
        [
            MAVPROXY,
            f"--master=udpin:127.0.0.1:{api_base}",
            "--mav20",
            f"--target-system={sysid}",
            f"--state-basedir={tmp_path}",
        ],
        tmp_path,
    )


def test_mavproxy_arms_takes_off_and_lands(tmp_path: Path) -> None:
    scenario, gcs_port, api_base = write_scenario(tmp_path / "scenario.toml", 2)
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp_path, ["uav1", "uav2"], backend="real"),
        gateway(net, scenario, tmp_path, "cmd_timeout_s=3"),
        MavClient(gcs_port) as watch,
    ):
        watch.wait_standby(1)
        console = mavproxy_console(api_base, 1, tmp_path)
        try:
            console.expect("Detected vehicle 1:1")
            console.expect("parameters")  # it fetched the parameter list
            console.type("arm throttle")
            console.expect("COMPONENT_ARM_DISARM: ACCEPTED")
            console.type("takeoff 7")  # relative altitude, lat/lon 0
            console.expect("NAV_TAKEOFF: ACCEPTED")
            watch.wait_above(1, 6.5)  # at 7 m
            console.type("long MAV_CMD_NAV_LAND")  # `mode land` trips MAVProxy on PX4 modes
            console.expect("NAV_LAND: ACCEPTED")
            watch.wait_disarmed(1, 180.0)
            console.expect("DISARMED")
        finally:
            console.close()
