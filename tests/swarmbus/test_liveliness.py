"""Presence: B sees A's liveliness token appear, and disappear when A is SIGKILLed."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from functools import partial

import zenoh

from swarmbus.session import NetworkConfig, Presence, open_session
from tests.support.procs import REPO, Network, keys_for


def _note(changes: list[tuple[str, bool]], name: str, alive: bool) -> None:
    changes.append((name, alive))


def test_token_appears_and_disappears_on_sigkill(network: tuple[Network, zenoh.Session]) -> None:
    net, router = network
    changes: list[tuple[str, bool]] = []
    presence = Presence(router, keys_for(), on_change=lambda n, a: changes.append((n, a)))
    env = dict(os.environ, PYTHONPATH=str(REPO))
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.support.liveliness_peer", net.endpoint, "node-a"],
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


def test_sync_knows_the_present_tokens_when_it_returns(
    network: tuple[Network, zenoh.Session],
) -> None:
    """A token already on the bus is known once ``sync()`` returns, without waiting for the
    subscriber's history; a token that left since is not resurrected, and each arrival is
    reported once even when both the history and the query bring it."""
    net, router = network
    keys = keys_for()
    with open_session(NetworkConfig(connect=[net.endpoint], listen=[])) as peer:
        tokens = [peer.liveliness().declare_token(keys.node_health(f"early-{k}")) for k in range(3)]
        probe = Presence(router, keys)  # tokens seen from the router's side first
        assert probe.wait_for(lambda a: {"early-0", "early-1", "early-2"} <= a, 30.0)
        probe.close()
        for _ in range(5):  # several fresh observers: each knows all three on return
            changes: list[tuple[str, bool]] = []
            presence = Presence(router, keys, on_change=partial(_note, changes))
            presence.sync(timeout_s=5.0)
            assert {"early-0", "early-1", "early-2"} <= presence.alive
            presence.wait_for(lambda a: False, 0.2)  # let the history arrive as well
            assert sorted(changes) == [("early-0", True), ("early-1", True), ("early-2", True)]
            presence.close()
        presence = Presence(router, keys)
        assert presence.wait_for(lambda a: "early-2" in a, 30.0)
        tokens[2].undeclare()
        assert presence.wait_for(lambda a: "early-2" not in a, 30.0)
        presence.sync(timeout_s=5.0)
        assert "early-2" not in presence.alive
        presence.close()
        for t in tokens[:2]:
            t.undeclare()


def test_sync_with_a_swarm_of_tokens(network: tuple[Network, zenoh.Session]) -> None:
    """More tokens than a Zenoh channel holds by default (a 254-vehicle run has ~260): sync
    returns, knowing every one (it once hung here, with the physics stuck before tick 0)."""
    net, router = network
    keys = keys_for()
    with open_session(NetworkConfig(connect=[net.endpoint], listen=[])) as peer:
        names = [f"autopilot-uav{k}" for k in range(600)]
        tokens = [peer.liveliness().declare_token(keys.node_health(n)) for n in names]
        probe = Presence(router, keys)
        assert probe.wait_for(lambda a: set(names) <= a, 60.0)
        probe.close()
        presence = Presence(router, keys)
        worker = threading.Thread(target=presence.sync, kwargs={"timeout_s": 5.0}, daemon=True)
        worker.start()
        worker.join(30.0)
        assert not worker.is_alive(), "sync did not return"
        assert set(names) <= presence.alive
        presence.close()
        for t in tokens:
            t.undeclare()
