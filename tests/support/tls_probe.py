"""Probes of a TLS deployment's door and access control, in-process or as a script.

``forged_puts_seen`` proves a refusal without waiting for a silence: the publisher puts every
forged sample and then a marker on a key it may use, on the same session (one ordered link);
once the listener holds a marker, every forged sample put before it has had its chance. A
forged key that arrived anyway is reported.

As a script (inside a network namespace), prints one JSON object::

    python -m tests.support.tls_probe acl HOSTS_FILE HOST LISTENER_ROLE PUBLISHER_ROLE
    python -m tests.support.tls_probe door HOSTS_FILE HOST OTHER_CA_DIR
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgspec
import zenoh

from deploy.certs import OPERATOR, identity
from deploy.hosts import Deployment, load_deployment
from deploy.security import node_identity, own_of, secure_network
from swarmbus.keys import Keys, autopilot_node
from swarmbus.scenario import load_scenario, resolve_scenario_path
from swarmbus.session import NetworkConfig, TlsConfig, open_session, tls_settings, zenoh_config

FORGED = b"forged by the tls probe"
BLOCK = zenoh.CongestionControl.BLOCK  # a put dropped on a busy link would read as refused


def marker_of(dep: Deployment, host: str, role: str, keys: Keys, node: str | None = None) -> str:
    """A key the identity of ``role`` on ``host`` may put on: the health key of a node name
    of its own that no process uses (``<role>-probe``, ``autopilot-<id>-plusprobe``)."""
    own = own_of(dep, node_identity(dep, host, role, node))
    return keys.node_health(own.nodes[-1].replace("$*", "probe"))


def forbidden_keys(keys: Keys) -> list[str]:
    return [
        keys.autopilot_actuators(autopilot_node("uav1")),
        keys.vehicle_state("uav1"),
        keys.tick(),
    ]


def forged_puts_seen(
    listener: NetworkConfig,
    publisher: NetworkConfig,
    keys: Keys,
    timeout_s: float = 30.0,
    forged_keys: list[str] | None = None,
    *,
    marker_key: str,
) -> dict[str, Any]:
    """Which of ``forged_keys`` (default :func:`forbidden_keys`) the listener received from
    the publisher; the marker goes on ``marker_key`` (one the publisher may put on)."""
    forged = forged_keys if forged_keys is not None else forbidden_keys(keys)
    seen: set[str] = set()
    markers = threading.Event()
    # The router matches a session's subscriptions one at a time: the marker counts once it
    # came through every subscription that includes its key, so the forged keys' route (the
    # everything subscription) is up when the marker is seen.
    sub_keys = (keys.everything(), marker_key)
    needed = {i for i, k in enumerate(sub_keys) if zenoh.KeyExpr(k).includes(marker_key)}
    marked: set[int] = set()
    lock = threading.Lock()

    def on_sample_of(index: int) -> Callable[[zenoh.Sample], None]:
        def on_sample(sample: zenoh.Sample) -> None:
            payload = sample.payload.to_bytes()
            if payload == FORGED:
                seen.add(str(sample.key_expr))
            elif str(sample.key_expr) == marker_key:
                with lock:
                    marked.add(index)
                    if needed <= marked:
                        markers.set()

        return on_sample

    deadline = time.monotonic() + timeout_s
    sent = 0
    with open_session(listener) as ls:
        subs = [ls.declare_subscriber(k, on_sample_of(i)) for i, k in enumerate(sub_keys)]
        with open_session(publisher) as ps:
            while not markers.is_set() and time.monotonic() < deadline:
                for key in forged:
                    ps.put(key, FORGED, congestion_control=BLOCK)
                    sent += 1
                ps.put(marker_key, b"marker", congestion_control=BLOCK)
                markers.wait(0.2)
            # One more round after the first marker: routes are surely up for all keys now.
            markers.clear()
            with lock:
                marked.clear()
            for key in forged:
                ps.put(key, FORGED, congestion_control=BLOCK)
                sent += 1
            ps.put(marker_key, b"marker", congestion_control=BLOCK)
            markers.wait(max(0.0, deadline - time.monotonic()))
        for s in subs:
            s.undeclare()
    return {"marker": markers.is_set(), "seen": sorted(seen), "sent": sent}


def join_error(net: NetworkConfig, tls: dict[str, Any] | None) -> str | None:
    """The error of a client session opened with raw TLS settings ``tls``; None if it joined."""
    conf = zenoh_config(NetworkConfig(mode="client", connect=list(net.connect), listen=[]))
    for key, value in (tls or {}).items():
        conf.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    try:
        with zenoh.open(conf):
            return None
    except zenoh.ZError as exc:
        return str(exc)


def tokens_seen(
    net: NetworkConfig, keys: Keys, until_any_s: float = 0.0, query_s: float = 3.0
) -> list[str]:
    """The liveliness tokens ``net``'s identity is shown (a stranger: none). With
    ``until_any_s``, asks again until some are shown or that much time passed."""
    deadline = time.monotonic() + until_any_s
    with open_session(net) as s:
        while True:
            replies = s.liveliness().get(keys.all_node_health(), timeout=query_s)
            found = sorted(str(r.ok.key_expr) for r in replies if r.ok is not None)
            if found or time.monotonic() >= deadline:
                return found
            time.sleep(0.1)


def stranger_tls(authority_dir: Path, host_dir: Path, name: str) -> TlsConfig:
    """A certificate of the deployment's CA for an identity the ACL does not know."""
    from deploy.certs import Authority

    issued = Authority.load(authority_dir).issue_to(host_dir, name, ["127.0.0.1"], 1)
    return TlsConfig(
        root_ca=str(authority_dir / "ca.pem"), cert=str(issued.cert), key=str(issued.key)
    )


def door(
    dep: Deployment, host: str, keys: Keys, other_ca: Path, stranger: TlsConfig
) -> dict[str, Any]:
    """Who gets in: no certificate, another CA's, plain TCP, a stranger, and the operator."""
    base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
    ours = secure_network(base, dep, host, OPERATOR, keys)
    assert ours.tls is not None
    name = identity(OPERATOR, host)  # the same identity, signed by another CA
    foreign = TlsConfig(
        root_ca=str(other_ca / "ca.pem"),
        cert=str(other_ca / host / f"{name}.pem"),
        key=str(other_ca / host / f"{name}.key"),
    )
    no_cert = {"root_ca_certificate": ours.tls.root_ca}
    plain = NetworkConfig(connect=[dep.router.replace("tls/", "tcp/", 1)], listen=[])
    strange = msgspec.structs.replace(ours, tls=stranger)
    # The operator first: once it is shown the tokens, the stranger could be shown them too.
    operator_tokens = tokens_seen(ours, keys, until_any_s=30.0)
    return {
        "operator": join_error(base, tls_settings(ours.tls)),
        "no_cert": join_error(base, no_cert),
        "other_ca": join_error(base, tls_settings(foreign)),
        "plain_tcp": join_error(plain, None),
        "stranger_tokens": tokens_seen(strange, keys),
        "operator_tokens": operator_tokens,
    }


def main(argv: list[str]) -> int:
    """``acl HOSTS HOST LISTENER_ROLE PUBLISHER_ROLE`` or ``door HOSTS HOST OTHER_CA_DIR``."""
    what, hosts_file, host = argv[:3]
    dep = load_deployment(Path(hosts_file))
    keys = Keys(load_scenario(resolve_scenario_path(dep.scenario)).world.name)
    if what == "acl":  # clients: everything goes through the router and its ACL
        base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
        listener = secure_network(base, dep, host, argv[3], keys)
        publisher = secure_network(base, dep, host, argv[4], keys)
        marker = marker_of(dep, host, argv[4], keys)
        result = forged_puts_seen(listener, publisher, keys, marker_key=marker)
    else:
        assert dep.tls is not None
        certs = Path(dep.tls.certs)
        stranger = stranger_tls(certs, certs / "strangers", f"stranger.{host}")
        result = door(dep, host, keys, Path(argv[3]), stranger)
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
