"""A force disarm of an airborne vehicle across network namespaces, over mutual TLS with the
access-control list: the check of ``tests/deploy/test_tls_acl_airborne.py`` with each process
in its own host's namespace, the way three machines would run it.

The router and the physics run in ``sim``, uav1's autopilot in ``agents`` (each a real
``plumeswarm node`` inside ``ip netns exec``); a probe in ``gcs`` (``tests/support/airborne.py``)
takes uav1 off to 10 m with an operator's certificate, then sends ``Disarm(force=True)`` on four
key expressions from every certificate but the gateway's, an operator's and uav1's own (router,
physics, plume, recorder, viewer, uav2's autopilot, foxglove, ros2), on sessions that enforce
nothing themselves. Nobody answers, the router's log names each refused disarm with its sender,
uav1 stays armed and holding, never below 9 m; the gateway's certificate then sends the same
disarm from ``gcs`` and uav1 disarms (so the refusals were not vacuous). Needs root.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from deploy.hosts import load_deployment
from tests.deploy.test_tls_acl_airborne import ALTITUDE_M, SCENARIO, refused_and_logged
from tests.deploy.test_tls_acl_commands import COMMANDERS, ROLES, identities
from tests.deploy.test_tls_acl_refusals import start_router
from tests.support.hosts import write_hosts
from tests.support.procs import Network, NodeProcs, run_cli
from tests.system.test_netns_deploy import (
    ADDRESSES,
    ROUTER,
    Hosts,
    netns_of,
    three_namespaces,
)

pytestmark = pytest.mark.netns


def test_a_force_disarm_of_an_airborne_vehicle_from_another_namespace_is_refused(
    tmp_path: Path,
) -> None:
    hosts_file = write_hosts(
        tmp_path / "hosts.toml", ROUTER.replace("tcp/", "tls/", 1), ROLES, ADDRESSES,
        tls_certs="certs", per_vehicle_acl=True, vehicles={"agents": ["uav1", "uav2"]},
    )  # fmt: skip
    res = run_cli(["certs", "generate", "--hosts", str(hosts_file)])
    assert res.returncode == 0, res.stderr
    dep = load_deployment(hosts_file)
    others = sorted({f"{node or role}.{host}" for host, role, node in identities(dep)} - COMMANDERS)
    # router, physics, plume, recorder, viewer, uav2's autopilot, foxglove, ros2
    assert len(others) == 8, others
    scenario = tmp_path / "scenario.toml"
    scenario.write_text(SCENARIO)
    with three_namespaces() as ns, NodeProcs(Network(0), log_dir=tmp_path) as procs:

        def inside(host: str) -> list[str]:
            return ["ip", "netns", "exec", ns[host]]

        router_log = start_router(procs, tmp_path, prefix=inside("sim"))
        secured = ["--scenario", str(scenario), "--hosts", str(hosts_file)]
        physics = procs.start_module("plumeswarm", "node", "physics", *secured, "--host", "sim",
                                     label="physics", prefix=inside("sim"))  # fmt: skip
        uav1 = procs.start_module("plumeswarm", "node", "autopilot", "--vehicle", "uav1",
                                  *secured, "--host", "agents", label="uav1",
                                  prefix=inside("agents"))  # fmt: skip
        probe = Hosts(ns, hosts_file, tmp_path).run(
            "gcs", str(hosts_file), str(scenario), "gcs", str(ALTITUDE_M), *others,
            timeout_s=400, module="tests.support.airborne",
        )  # fmt: skip
        assert probe.returncode == 0, probe.stdout[-2000:] + probe.stderr[-3000:]
        # `ip netns exec` execs the node (same pid), long in its host's namespace by now.
        spaces = {netns_of(physics.pid), netns_of(uav1.pid), netns_of(os.getpid())}
        assert len(spaces) == 3, "physics, uav1's autopilot and this test share a namespace"
        result: dict[str, Any] = json.loads(probe.stdout.strip().splitlines()[-1])
        refused_and_logged(result["answered"], others, router_log)
        assert result["holding"], result
        lowest = result["lowest_m"]
        assert lowest > ALTITUDE_M - 1.0, f"uav1 sank to {lowest:.2f} m while refused disarms came"
        assert result["gateway_accepted"] and result["disarmed"], result
        print(f"\nrefused force disarms from {len(others)} certificates; lowest {lowest:.2f} m")
