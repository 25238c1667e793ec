"""Identities (``<role>.<host>``, ``operator.<host>``, per-vehicle ``autopilot-<id>.<host>``), TLS
settings and the Zenoh access-control list of a deployment's hosts file. See docs/deploy.md
("Over mutual TLS, with access control").
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import msgspec

from agents.swarm import CLOCK_CLIENT_PREFIX
from deploy.certs import OPERATOR, HostIdentities, identity
from deploy.hosts import Deployment, HostsError
from deploy.launcher import LaunchOptions
from swarmbus.keys import ROUTER_ADMIN, Keys, autopilot_node, vehicle_of_autopilot
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


# -- the role table ---------------------------------------------------------------------------
# What each identity may send (ingress) beyond what every identity may: the planes of its role.
# Every identity may also subscribe anywhere, query the plume and the router, receive anything,
# and declare its presence (token and health) under its own node names. `[acl] actuators`,
# `world`, `field` and `commands` move the planes of the same name to other roles.
ROLE_PLANES: dict[str, tuple[str, ...]] = {
    "router": ("everything",),  # forwards what others sent, checked where it entered
    "physics": ("world", "stepping"),
    "plume": ("field", "plume-service"),
    "autopilot": ("actuators", "readings", "vehicle-service"),
    "gateway": ("commands",),
    OPERATOR: ("commands", "restarts"),
    "recorder": (),
    "viewer": (),
    "foxglove": (),
    "ros2": ("ros2-graph",),
}
CONFIGURABLE = ("actuators", "world", "field", "commands")  # `[acl] <plane> = [roles]`
ROS2_GRAPH = "@ros2_lv"  # rmw_zenoh's liveliness space, where the ros2 bridge announces itself
ROS2_DOMAINS = range(233)  # ROS 2 domain ids: the ros2 bridge's topics are `<domain id>/...`
ALL_KEYS = ["**", ROUTER_ADMIN, f"{ROS2_GRAPH}/**"]  # `**` crosses no `@...` chunk
PUT = ["put", "delete"]
SERVE = ["declare_queryable", "reply"]
READ = ["declare_subscriber", "liveliness_query", "declare_liveliness_subscriber"]


@dataclass(frozen=True)
class Own:
    """What one identity speaks for, as key-expression chunks: its node names (presence,
    actuator batches) and its vehicles (``*`` for every vehicle)."""

    nodes: tuple[str, ...]
    vehicles: tuple[str, ...]


def planes_of(dep: Deployment, role: str) -> list[str]:
    """The planes ``role`` may send on: its row of :data:`ROLE_PLANES`, with the configurable
    planes given to the roles ``[acl]`` names."""
    fixed = [p for p in ROLE_PLANES.get(role, ()) if p not in CONFIGURABLE or role == OPERATOR]
    moved = [p for p in CONFIGURABLE if role in getattr(dep.acl, p)]
    return list(dict.fromkeys([*fixed, *moved]))


def own_of(dep: Deployment, name: str) -> Own:
    """The node names and vehicles of identity ``name`` (``<role>.<host>``)."""
    role, _, host = name.partition(".")
    vid = vehicle_of_autopilot(role)
    if vid is not None:  # a per-vehicle identity
        return Own((role,), (vid,))
    if role == OPERATOR:
        return Own((OPERATOR, f"{OPERATOR}-$*", f"{CLOCK_CLIENT_PREFIX}$*"), ("*",))
    vehicles = dep.host(host).vehicles if role == "autopilot" else None
    if not vehicles:
        return Own((role, f"{role}-$*"), ("*",))
    nodes = [vehicle_node(v) for v in vehicles] + [f"{vehicle_node(v)}-plus$*" for v in vehicles]
    return Own(tuple(nodes), tuple(vehicles))


def plane_grants(keys: Keys, plane: str, own: Own, role: str) -> list[tuple[list[str], list[str]]]:
    """(messages, key expressions) that ``plane`` allows an identity to send."""

    def vehicles(*leaves: str) -> list[str]:
        return [keys.owned("vehicle", v, leaf) for v in own.vehicles for leaf in leaves]

    presence = [keys.owned("node", n, "health") for n in own.nodes]
    drivers = own.nodes if role == "autopilot" or vehicle_of_autopilot(role) else ("*",)
    grants: dict[str, list[tuple[list[str], list[str]]]] = {
        "everything": [(list(MESSAGES), ALL_KEYS)],
        "presence": [(PUT, presence), (["liveliness_token"], presence)],
        "read": [
            (READ, ALL_KEYS),
            (
                ["query"],
                [keys.plume_concentration(), keys.plume_info(), keys.plume_mesh(), ROUTER_ADMIN],
            ),
        ],
        "receive": [(list(MESSAGES), ALL_KEYS)],
        "world": [
            (
                PUT,
                [
                    keys.tick(),
                    keys.sensor_tick(),
                    keys.clock(),
                    keys.all_vehicle_states(),
                    keys.backfill(),
                ],
            ),
        ],
        "stepping": [(SERVE, [keys.clock_step()])],
        "field": [(PUT, [keys.plume_sample(), keys.plume_state()])],
        "plume-service": [
            (SERVE, [keys.plume_concentration(), keys.plume_info(), keys.plume_mesh()])
        ],
        "actuators": [(PUT, [keys.owned("autopilot", n, "actuators") for n in drivers])],
        "readings": [(PUT, vehicles("status", "concentration", "wind"))],
        # A vehicle's own autopilot serves its commands and may send itself one.
        "vehicle-service": [(SERVE, vehicles("cmd")), (["query"], vehicles("cmd"))],
        "commands": [(["query"], [keys.owned("vehicle", "*", "cmd"), keys.clock_step()])],
        "restarts": [(PUT, [keys.all_node_restart()])],
        "ros2-graph": [
            (PUT, [f"{d}/**" for d in ROS2_DOMAINS]),
            (["liveliness_token"], [f"{ROS2_GRAPH}/**"]),
        ],
    }
    return grants[plane]


def access_control(dep: Deployment, keys: Keys, enforcer: str = "") -> dict[str, Any]:
    """Zenoh's ``access_control`` section for ``dep``: default deny; each identity of the
    hosts file its own policy, made of the planes of its role (:data:`ROLE_PLANES`).
    ``enforcer``: the role of the process that enforces it; the router itself grants nothing
    to the router's identity (one router: a link that shows its certificate is not it)."""
    everyone = sorted({n for h in host_identities(dep) for n in h.identities})
    names = [n for n in everyone if enforcer != "router" or _role_of(n) != "router"]
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []
    for name in names:
        role = _role_of(name)
        kind = "autopilot" if vehicle_of_autopilot(role) else role
        own = own_of(dep, name)
        ids = []
        for plane in ["presence", "read", "receive", *planes_of(dep, kind)]:
            for i, (messages, key_exprs) in enumerate(plane_grants(keys, plane, own, role)):
                ids.append(f"{name}/{plane}/{i}")
                rules.append(
                    {
                        "id": ids[-1],
                        "permission": "allow",
                        "flows": ["egress"] if plane == "receive" else ["ingress"],
                        "messages": messages,
                        "key_exprs": key_exprs,
                    }
                )
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"rules": ids, "subjects": [name]})
    # An identity granted nothing here is still a subject, so that what it sends is refused
    # under its name (the refusal log names the sender by its subject).
    subjects += [{"id": n, "cert_common_names": [n]} for n in everyone if n not in names]
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


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
    acl = access_control(dep, keys, role) if dep.acl.enabled else None
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
