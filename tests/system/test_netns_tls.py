"""Three hosts (network namespaces) on Zenoh over mutual TLS with the access-control list.

The deployment of ``test_netns_deploy.py`` with a ``[tls]`` hosts file and the certificates of
``plumeswarm certs generate``: every link between the namespaces is ``tls/``. Probes run inside
the ``gcs`` and ``agents`` namespaces (``tests/support/tls_probe.py``): clients without a
certificate, with another CA's or over plain TCP do not get in; a certificate of our CA with an
unknown name is shown nothing; a gateway identity that publishes actuators and states, and an
autopilot identity that publishes states, are refused at the router (a legitimate subscriber
never sees them, while the autopilot's own actuators do pass), and the router's log names each
of those refusals with its key and identity; then the seed scenario flies. Needs root.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from deploy import certs
from deploy.hosts import load_deployment
from deploy.security import host_identities
from swarmbus.keys import Keys
from tests.deploy.test_tls_acl_refusals import refused
from tests.support.procs import run_cli, wait_until
from tests.support.tls_probe import forbidden_keys
from tests.system.test_netns_deploy import Hosts, fly_demo, netns_of, three_namespaces, write_hosts

pytestmark = pytest.mark.netns
KEYS = Keys("default")


def probe(h: Hosts, host: str, *args: str) -> dict[str, Any]:
    res = h.run(host, *args, timeout_s=180, module="tests.support.tls_probe")
    assert res.returncode == 0, res.stdout[-2000:] + res.stderr[-3000:]
    result: dict[str, Any] = json.loads(res.stdout.strip().splitlines()[-1])
    return result


def leaves(keys: list[str]) -> set[str]:
    return {k.rsplit("/", 1)[-1] for k in keys}


def test_seed_scenario_flies_over_mutual_tls_and_strangers_stay_out(tmp_path: Path) -> None:
    gcs_roles = ["gateway"]
    roles = {"sim": ["router", "physics", "plume"], "agents": ["autopilot"], "gcs": gcs_roles}
    with three_namespaces() as ns:
        hosts_file = write_hosts(tmp_path / "hosts.toml", roles, tls_certs="certs")
        res = run_cli(["certs", "generate", "--hosts", str(hosts_file)])
        assert res.returncode == 0, res.stderr
        dep = load_deployment(hosts_file)
        certs.generate(host_identities(dep), tmp_path / "other-ca", days=1)
        h = Hosts(ns, hosts_file, tmp_path, stepped=True)
        try:
            sim = h.up("sim")
            agents = h.up("agents")
            if gcs_roles:
                h.up("gcs")
            assert netns_of(sim["physics"]) != netns_of(agents["autopilot-uav1"])
            assert netns_of(sim["physics"]) != netns_of(os.getpid())

            door = probe(h, "gcs", "door", str(hosts_file), "gcs", str(tmp_path / "other-ca"))
            assert door["operator"] is None, door
            assert KEYS.node_health("physics") in door["operator_tokens"], door
            assert KEYS.node_health("autopilot-uav1") in door["operator_tokens"], door
            for stranger in ("no_cert", "other_ca", "plain_tcp"):
                assert door[stranger] is not None, f"{stranger} joined: {door}"
            assert door["stranger_tokens"] == [], door

            gateway = probe(h, "gcs", "acl", str(hosts_file), "gcs", "operator", "gateway")
            assert gateway["marker"] and gateway["seen"] == [], gateway
            autopilot = probe(
                h, "agents", "acl", str(hosts_file), "agents", "operator", "autopilot"
            )
            assert autopilot["marker"], autopilot
            assert leaves(autopilot["seen"]) == {"actuators"}, autopilot
            assert len(forbidden_keys(KEYS)) == 3
            # ... and each refusal is named in the router's log, with its key and identity
            forged = {("put", k) for k in forbidden_keys(KEYS)}
            router_log = tmp_path / "sim" / "router.log"
            wait_until(
                lambda: forged <= refused(router_log, "gateway.gcs"), 30.0, "gateway's lines"
            )
            actuators = ("put", forbidden_keys(KEYS)[0])
            wait_until(
                lambda: forged - {actuators} <= refused(router_log, "autopilot.agents"),
                30.0, "the autopilot's lines",
            )  # fmt: skip
            assert actuators not in refused(router_log, "autopilot.agents")
            sent = (gateway["sent"], autopilot["sent"])
            print(f"\nforged samples refused: gateway {sent[0]}, autopilot {sent[1]}")

            summary = fly_demo(
                h, tmp_path / "demo", dep.router, "--hosts", str(hosts_file), "--host", "gcs"
            )
            print(
                f"\nseed scenario over mTLS + ACL: real-time factor {summary['real_time_factor']}"
            )
        finally:
            h.stop()
        # Every link between our own processes showed a certificate of an identity: only the
        # router met one that names none (the probe's stranger). A process listening on plain
        # TCP beside mTLS (the demo's session, once) would show up here.
        strangers = [
            f.relative_to(tmp_path)
            for f in tmp_path.glob("*/*.log")
            if "names no identity" in f.read_text(errors="replace")
        ]
        assert strangers == [Path("sim/router.log")], strangers
