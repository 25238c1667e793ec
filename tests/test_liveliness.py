"""Presence: B sees A's liveliness token appear, and disappear when A is SIGKILLed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys

import zenoh

from swarmbus.session import Presence
from tests.procs import REPO, Network, keys_for


def test_token_appears_and_disappears_on_sigkill(network: tuple[Network, zenoh.Session]) -> None:
    net, router = network
    changes: list[tuple[str, bool]] = []
    presence = Presence(router, keys_for(), on_change=lambda n, a: changes.append((n, a)))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.liveliness_peer", net.endpoint, "node-a"],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        assert presence.wait_for(lambda alive: "node-a" in alive, 30.0), "node-a never appeared"
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        assert presence.wait_for(lambda alive: "node-a" not in alive, 30.0), (
            "node-a still alive after SIGKILL"
        )
        assert changes == [("node-a", True), ("node-a", False)]
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
        assert proc.stdout is not None
        proc.stdout.close()
        presence.close()
