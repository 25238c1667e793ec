"""What mutual TLS and the access-control list cost: ping-pong through a router on loopback.

Run: ``python -m plumeswarm.bench.tls``. Two client sessions (the ``physics`` and ``autopilot``
identities of
a generated deployment) bounce a 100-byte sample through an in-process router: ping on a
state key, pong on an actuators key, as in the lockstep. Prints a table; no assertions.
``--refusal-log``: the ACL's trace on and read for refusals (``swarmbus.refusals``), as every
``plumeswarm node`` under an ACL runs; here the router and both clients share that one reader.
"""

from __future__ import annotations

import argparse
import statistics
import tempfile
import threading
import time
from pathlib import Path

import msgspec

from deploy import certs
from deploy.hosts import AclSection, Deployment, Host, TlsSection
from deploy.security import host_identities, secure_network
from swarmbus.keys import Keys, autopilot_node
from swarmbus.refusals import watch
from swarmbus.session import NetworkConfig, free_tcp_port, open_session

KEYS = Keys("bench")


def deployment(scheme: str, port: int, certs_dir: Path, acl: bool) -> Deployment:
    return Deployment(
        router=f"{scheme}/127.0.0.1:{port}",
        tls=TlsSection(certs=str(certs_dir)) if scheme == "tls" else None,
        acl=AclSection(enabled=acl),
        hosts=[
            Host(name="sim", address="127.0.0.1", roles=["router", "physics"]),
            Host(name="agents", address="127.0.0.1", roles=["autopilot"]),
        ],
    )


def round_trips(dep: Deployment, n: int) -> list[float]:
    def net(host: str, role: str, **kw: object) -> NetworkConfig:
        base = NetworkConfig(mode="client", connect=[dep.router], listen=[])
        return msgspec.structs.replace(secure_network(base, dep, host, role, KEYS), **kw)

    router = net("sim", "router", mode="router", connect=[], listen=[dep.router])
    ping_key, pong_key = (
        KEYS.vehicle_state("uav1"),
        KEYS.autopilot_actuators(autopilot_node("uav1")),
    )
    got = threading.Event()
    payload = bytes(100)
    with (
        open_session(router),
        open_session(net("sim", "physics")) as physics,
        open_session(net("agents", "autopilot")) as autopilot,
    ):
        pong = autopilot.declare_publisher(pong_key)
        sub_a = autopilot.declare_subscriber(ping_key, lambda s: pong.put(payload))
        sub_p = physics.declare_subscriber(pong_key, lambda s: got.set())
        ping = physics.declare_publisher(ping_key)
        deadline = time.monotonic() + 30
        while not got.is_set():  # routes up
            ping.put(payload)
            got.wait(0.1)
            if time.monotonic() > deadline:
                raise RuntimeError(f"no pong via {dep.router}")
        rtts = []
        for _ in range(n):
            got.clear()
            t0 = time.perf_counter()
            ping.put(payload)
            if not got.wait(5.0):
                raise RuntimeError("pong lost")
            rtts.append(time.perf_counter() - t0)
        sub_a.undeclare()
        sub_p.undeclare()
    return rtts


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("-n", type=int, default=1000, help="round trips per row and round")
    parser.add_argument("--rounds", type=int, default=3, help="rows interleaved this often")
    parser.add_argument(
        "--refusal-log", action="store_true", help="log ACL refusals (trace on) as nodes do"
    )
    args = parser.parse_args()
    if args.refusal_log:
        watch()
    with tempfile.TemporaryDirectory() as tmp:
        certs_dir = Path(tmp) / "certs"
        certs.generate(host_identities(deployment("tls", 1, certs_dir, True)), certs_dir, days=1)
        rows = [("tcp", False), ("tls", False), ("tls", True)]
        # Interleaved rounds: a shared machine's load drifts; each row sees all of it.
        samples: dict[tuple[str, bool], list[float]] = {r: [] for r in rows}
        for _ in range(args.rounds):
            for scheme, acl in rows:
                dep = deployment(scheme, free_tcp_port(), certs_dir, acl)
                samples[(scheme, acl)] += round_trips(dep, args.n)
        print(f"{'link':22} {'p50 µs':>8} {'p99 µs':>8} {'round trips/s':>14}")
        for (scheme, acl), values in samples.items():
            rtts = sorted(values)
            p50 = statistics.median(rtts) * 1e6
            p99 = rtts[int(0.99 * (len(rtts) - 1))] * 1e6
            label = f"{scheme}{' + mTLS' if scheme == 'tls' else ''}{' + ACL' if acl else ''}"
            print(f"{label:22} {p50:8.0f} {p99:8.0f} {len(rtts) / sum(rtts):14.0f}")


if __name__ == "__main__":
    main()
