"""Identities (``<role>.<host>``, ``operator.<host>``, per-vehicle ``autopilot-<id>.<host>``), TLS
settings and the Zenoh access-control list of a deployment's hosts file. See docs/deploy.md
("Over mutual TLS, with access control").
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any

import msgspec

from deploy.certs import OPERATOR, HostIdentities, identity
from deploy.hosts import Deployment, HostsError
from deploy.launcher import LaunchOptions
from swarmbus.keys import ROUTER_ADMIN, Keys, autopilot_node
from swarmbus.session import (
    NetworkConfig,
    NetworkConfigError,
    TlsConfig,
    check_tls_files,
)

MESSAGES = (
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "reply",
    "declare_queryable",
    "liveliness_token",
    "liveliness_query",
    "declare_liveliness_subscriber",
)


def host_identities(dep: Deployment) -> list[HostIdentities]:
    """Per host: its address(es) and the identities of its roles and its operator."""
    out = []
    for h in dep.hosts:
        addresses = [h.address] if h.address else []
        addresses += [_address_of(e) for e in h.listen]
        if "router" in h.roles:
            addresses.append(_address_of(dep.router))
        roles = [r for r in dict.fromkeys([*h.roles, OPERATOR])]
        if dep.acl.per_vehicle and "autopilot" in roles:
            roles.remove("autopilot")
            roles += [vehicle_node(v) for v in h.vehicles or ()]
        names = [identity(r, h.name) for r in roles]
        out.append(HostIdentities(h.name, tuple(dict.fromkeys(addresses)), tuple(names)))
    return out


def per_vehicle_identities(dep: Deployment) -> dict[str, str]:
    """Vehicle id → the identity of its autopilot (``[acl] per_vehicle``; else empty)."""
    if not dep.acl.per_vehicle:
        return {}
    return {
        vid: identity(vehicle_node(vid), h.name)
        for h in dep.hosts
        if "autopilot" in h.roles
        for vid in h.vehicles or ()
    }


def vehicle_node(vehicle_id: str) -> str:
    """The node name of the autopilot process of one vehicle (its per-vehicle identity)."""
    return autopilot_node(vehicle_id)


def node_identity(dep: Deployment, host: str, role: str, node_name: str | None) -> str:
    """The identity a process of ``role`` (named ``node_name``) runs as on ``host``."""
    if dep.acl.per_vehicle and role == "autopilot":
        vehicles = dep.host(host).vehicles or []
        if node_name not in [vehicle_node(v) for v in vehicles]:
            raise HostsError(
                f"[acl] per_vehicle: {node_name or 'this autopilot'} is not the autopilot of "
                f"one vehicle of host {host} ({', '.join(vehicles)}); run one vehicle per process"
            )
        return identity(node_name, host)
    return identity(role, host)


def _address_of(endpoint: str) -> str:
    host = endpoint.partition("/")[2].rpartition(":")[0]
    return host.strip("[]")


def _role_of(name: str) -> str:
    return name.partition(".")[0]


def access_control(dep: Deployment, keys: Keys) -> dict[str, Any]:
    """Zenoh's ``access_control`` section for ``dep``."""
    per_vehicle = set(per_vehicle_identities(dep).values())  # each with its own rules, below
    members = sorted(n for h in host_identities(dep) for n in h.identities if n not in per_vehicle)
    rules: list[dict[str, Any]] = [
        {
            "id": "members",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": list(MESSAGES),
            "key_exprs": ["**", ROUTER_ADMIN],
        }
    ]
    subjects: list[dict[str, Any]] = [{"id": "members", "cert_common_names": members}]
    policies: list[dict[str, Any]] = [{"rules": ["members"], "subjects": ["members"]}]
    planes = {
        "actuators": (
            [keys.all_autopilot_actuators()],
            dep.acl.actuators,
        ),
        "world": (
            [
                keys.tick(),
                keys.sensor_tick(),
                keys.clock(),
                keys.all_vehicle_states(),
                keys.backfill(),
            ],
            dep.acl.world,
        ),
        "field": ([keys.plume_sample(), keys.plume_state()], dep.acl.field),
    }
    for plane, (key_exprs, roles) in planes.items():
        others = [n for n in members if _role_of(n) not in {*roles, "router"}]
        if not others:
            continue
        rules.append(
            {
                "id": f"publish-{plane}",
                "permission": "deny",
                "flows": ["ingress"],
                "messages": ["put", "delete"],
                "key_exprs": key_exprs,
            }
        )
        subjects.append({"id": f"not-{plane}-publishers", "cert_common_names": others})
        policies.append({"rules": [f"publish-{plane}"], "subjects": [f"not-{plane}-publishers"]})
    if dep.acl.per_vehicle:
        rules += _shared_vehicle_rules()
        for vid, name in per_vehicle_identities(dep).items():
            own = _vehicle_rules(keys, vid)
            rules += own
            subject = vehicle_node(vid)
            subjects.append({"id": subject, "cert_common_names": [name]})
            policies.append(
                {
                    "rules": [r["id"] for r in own] + ["read-anything", "receive-anything"],
                    "subjects": [subject],
                }
            )
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _vehicle_rules(keys: Keys, vehicle_id: str) -> list[dict[str, Any]]:
    """What a per-vehicle identity may send (ingress): its own vehicle's data and answers."""
    node = vehicle_node(vehicle_id)
    own_data = [
        keys.vehicle_status(vehicle_id),
        keys.vehicle_concentration(vehicle_id),
        keys.autopilot_actuators(node),
        keys.node_health(node),
    ]
    grants = [
        ("data", ["put", "delete"], own_data),
        ("presence", ["liveliness_token"], [keys.node_health(node)]),
        ("commands", ["declare_queryable", "reply"], [keys.vehicle_cmd(vehicle_id)]),
    ]
    return [
        {
            "id": f"{node}-{what}",
            "permission": "allow",
            "flows": ["ingress"],
            "messages": messages,
            "key_exprs": key_exprs,
        }
        for what, messages, key_exprs in grants
    ]


def _shared_vehicle_rules() -> list[dict[str, Any]]:
    """Every per-vehicle identity may subscribe and query anywhere, and receive anything."""
    return [
        {
            "id": "read-anything",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ["declare_subscriber", "query", "liveliness_query",
                         "declare_liveliness_subscriber"],
            "key_exprs": ["**", ROUTER_ADMIN],
        },
        {
            "id": "receive-anything",
            "permission": "allow",
            "flows": ["egress"],
            "messages": list(MESSAGES),
            "key_exprs": ["**", ROUTER_ADMIN],
        },
    ]  # fmt: skip


def tls_for(dep: Deployment, host: str, name: str) -> TlsConfig | None:
    """The TLS identity ``name`` on ``host`` (paths of ``certs generate``); None without TLS."""
    if dep.tls is None:
        return None
    dep.host(host)
    certs = Path(dep.tls.certs)
    return TlsConfig(
        root_ca=str(certs / "ca.pem"),
        cert=str(certs / host / f"{name}.pem"),
        key=str(certs / host / f"{name}.key"),
        verify_name=dep.tls.verify_name,
    )


def secure_network(
    net: NetworkConfig,
    dep: Deployment,
    host: str,
    role: str,
    keys: Keys,
    node_name: str | None = None,
) -> NetworkConfig:
    """``net`` as the identity of ``role`` on ``host`` (of ``node_name`` with per-vehicle
    identities): TLS and the access-control list.

    Raises :class:`HostsError` (one line) when a TLS file is missing or unreadable."""
    tls = tls_for(dep, host, node_identity(dep, host, role, node_name))
    if tls is None:
        return net
    try:
        check_tls_files(tls)
    except NetworkConfigError as exc:
        raise HostsError(f"{exc} (make them with `plumeswarm certs generate`)") from None
    acl = access_control(dep, keys) if dep.acl.enabled else None
    return msgspec.structs.replace(net, tls=tls, access_control=acl)


def secure_launch(
    opts: LaunchOptions,
    dep: Deployment,
    hosts_file: Path,
    host: str,
    net: NetworkConfig,
    keys: Keys,
) -> LaunchOptions:
    """``opts`` of one host with TLS: every node gets ``--hosts/--host`` (its identity) and the
    launcher's own session runs as the host's operator."""
    if dep.tls is None:
        return opts
    if dep.acl.per_vehicle and "autopilot" in dep.host(host).roles:
        if opts.vehicles_per_process > 1:
            raise HostsError("[acl] per_vehicle: one vehicle per autopilot process")
        for vid in dep.host(host).vehicles or ():
            secure_network(net, dep, host, "autopilot", keys, vehicle_node(vid))
    for role in dep.host(host).roles:
        if not (dep.acl.per_vehicle and role == "autopilot"):
            secure_network(net, dep, host, role, keys)  # fail before anything starts
    return replace(
        opts,
        node_args=("--hosts", str(hosts_file.absolute()), "--host", host),
        client_network=secure_network(net, dep, host, OPERATOR, keys),
    )
