"""Starting what the gateway tests fly against: the gateway process, and either the scripted
fake autopilot (tests/support/fake_autopilot.py) or the real stack (plume + physics +
autopilots). A vehicle the fake skips is the test's to play, on the fake's own bus side
(``fake_autopilot.FakeAutopilot``) with replies of its choosing."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from tests.support.procs import REPO, Network


def spawn(args: list[str], log: Path) -> subprocess.Popen[bytes]:
    out = open(log, "wb")  # noqa: SIM115 - the child keeps its own descriptor
    env = dict(os.environ, PYTHONPATH=str(REPO), PYTHONUNBUFFERED="1")
    proc = subprocess.Popen(
        [sys.executable, *args],
        cwd=REPO,
        stdout=out,
        stderr=subprocess.STDOUT,
        env=env,
        start_new_session=True,
    )
    out.close()
    return proc


def stop(proc: subprocess.Popen[bytes]) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=5)


def node(net: Network, role: str, scenario: Path, log: Path, *args: str) -> subprocess.Popen[bytes]:
    return spawn(
        [
            "-m",
            "plumeswarm",
            "-v",
            "node",
            role,
            *net.cli_args(),
            "--scenario",
            str(scenario),
            *args,
        ],
        log,
    )


@contextmanager
def gateway(
    net: Network, scenario: Path, log_dir: Path, *sets: str
) -> Iterator[subprocess.Popen[bytes]]:
    args = [a for s in sets for a in ("--set", s)]
    proc = node(net, "gateway", scenario, log_dir / "gateway.log", *args)
    try:
        yield proc
    finally:
        stop(proc)


@contextmanager
def vehicles(
    net: Network,
    scenario: Path,
    log_dir: Path,
    ids: list[str],
    backend: str = "fake",
    speed: float = 3.0,
    skip: tuple[str, ...] = (),
) -> Iterator[list[subprocess.Popen[bytes]]]:
    """The vehicles' side of the bus: the fake at ``speed`` × real time, or the real stack."""
    procs: list[subprocess.Popen[bytes]] = []
    try:
        if backend == "fake":
            args = [
                "-m",
                "tests.support.fake_autopilot",
                "--connect",
                net.endpoint,
                "--scenario",
                str(scenario),
                "--speed",
                str(speed),
            ]
            for vid in skip:
                args += ["--skip", vid]
            procs.append(spawn(args, log_dir / "fake.log"))
        else:
            procs.append(node(net, "plume", scenario, log_dir / "plume.log"))
            for vid in ids:
                procs.append(
                    node(
                        net,
                        "autopilot",
                        scenario,
                        log_dir / f"autopilot-{vid}.log",
                        "--vehicle",
                        vid,
                    )
                )
            procs.append(node(net, "physics", scenario, log_dir / "physics.log"))
        yield procs
    finally:
        for p in reversed(procs):
            stop(p)
