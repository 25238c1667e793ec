"""The one writer of a deployment's hosts file for tests (docs/deploy.md, "Hosts")."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

# The usual split: the world on one host, the autopilots on another, the gateway on a third.
SPLIT_ROLES: dict[str, list[str]] = {
    "sim": ["router", "physics", "plume"],
    "agents": ["autopilot"],
    "gcs": ["gateway"],
}


def _strings(items: Sequence[str]) -> str:
    return "[" + ", ".join(f'"{i}"' for i in items) + "]"


def write_hosts(
    path: Path,
    router: str,
    roles: Mapping[str, Sequence[str]] = SPLIT_ROLES,
    addresses: Mapping[str, str] | str = "127.0.0.1",
    *,
    tls_certs: str | None = None,
    per_vehicle_acl: bool = False,
    vehicles: Mapping[str, Sequence[str]] | None = None,
) -> Path:
    """A hosts file: each host of ``roles`` at its address (one for all, or per host), listening
    on port 0 with ``tls/`` endpoints when ``tls_certs`` (the certificates' directory) is given,
    else ``tcp/``; ``vehicles``: the vehicles a host's autopilots serve."""
    scheme = "tls" if tls_certs else "tcp"
    lines = [f'router = "{router}"', ""]
    if tls_certs:
        lines += ["[tls]", f'certs = "{tls_certs}"', ""]
    if per_vehicle_acl:
        lines += ["[acl]", "per_vehicle = true", ""]
    for host, host_roles in roles.items():
        address = addresses if isinstance(addresses, str) else addresses[host]
        lines += ["[[hosts]]", f'name = "{host}"', f'address = "{address}"']
        lines += [f"roles = {_strings(host_roles)}"]
        if vehicles and host in vehicles:
            lines += [f"vehicles = {_strings(vehicles[host])}"]
        lines += [f'listen = ["{scheme}/{address}:0"]', ""]
    path.write_text("\n".join(lines))
    return path
