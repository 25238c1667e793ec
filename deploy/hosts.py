"""Deployment over several hosts: which roles run where, and the Zenoh endpoints between them.

A hosts file (see ``deploy/hosts.example.toml``) names one router endpoint that every process
connects to, and per host the roles it runs and the endpoint its processes listen on.
``plumeswarm up --hosts FILE --host NAME`` runs that host's share. With a ``[tls]`` section every
link is mutual TLS with the certificates of ``plumeswarm certs generate`` and every process
enforces the ``[acl]`` (see :mod:`deploy.security`).
"""

from __future__ import annotations

import tomllib
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import msgspec

from deploy.launcher import ALL_ROLES, LaunchOptions
from swarmbus.errors import PlumeswarmError
from swarmbus.scenario_errors import explain
from swarmbus.session import Endpoint

RoleName = Annotated[str, msgspec.Meta(pattern="^(" + "|".join(ALL_ROLES) + ")$")]


class HostsError(PlumeswarmError, ValueError):
    pass


class Host(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    name: str
    address: str = ""  # informational: how operators reach the machine
    roles: list[RoleName]
    vehicles: list[str] | None = None  # autopilots for these vehicles only
    listen: list[Endpoint] = msgspec.field(default_factory=list)


class TlsSection(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    certs: str  # directory written by `plumeswarm certs generate` (relative to the hosts file)
    verify_name: bool = True  # a host's certificate must name the address connected to


def _default_actuators() -> list[str]:
    return ["autopilot"]


def _default_world() -> list[str]:
    return ["physics"]


def _default_field() -> list[str]:
    return ["plume"]


def _default_commands() -> list[str]:
    return ["gateway"]


class AclSection(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Which roles produce the planes that may move to other roles; the rest of what each role
    may send is fixed by its role (``deploy.security.ROLE_PLANES``). Enforced only with
    ``[tls]`` (identities are the certificates' common names)."""

    enabled: bool = True
    actuators: list[RoleName] = msgspec.field(default_factory=_default_actuators)
    world: list[RoleName] = msgspec.field(default_factory=_default_world)  # ticks, states, clock
    field: list[RoleName] = msgspec.field(default_factory=_default_field)  # plume samples, state
    # Who may query vehicle/*/cmd and clock/step besides the operator and a vehicle's autopilot
    commands: list[RoleName] = msgspec.field(default_factory=_default_commands)
    # One identity per autopilot process (one vehicle each), allowed to speak for its own
    # vehicle only (deploy.security); the hosts running autopilots then list their vehicles.
    per_vehicle: bool = False


class Deployment(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    router: Endpoint
    scenario: str | None = None
    tls: TlsSection | None = None
    acl: AclSection = msgspec.field(default_factory=AclSection)
    hosts: list[Host]

    def host(self, name: str) -> Host:
        for h in self.hosts:
            if h.name == name:
                return h
        raise HostsError(f"no host {name!r} (hosts: {', '.join(h.name for h in self.hosts)})")


def load_deployment(path: Path) -> Deployment:
    try:
        raw = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise HostsError(f"{path}: {exc}") from None
    try:
        dep = msgspec.convert(raw, Deployment)
    except msgspec.ValidationError as exc:  # the key, the bad value, the valid values
        field, reason = explain(exc, raw, Deployment)
        raise HostsError(f"{path}: {field}: {reason}" if field else f"{path}: {reason}") from None
    owners = [h.name for h in dep.hosts if "router" in h.roles]
    if len(owners) != 1:
        raise HostsError(f"{path}: exactly one host must run the router, got {owners or 'none'}")
    names = [h.name for h in dep.hosts]
    if len(set(names)) != len(names):
        raise HostsError(f"{path}: host names must be unique, got {names}")
    endpoints = [dep.router, *(e for h in dep.hosts for e in h.listen)]
    if dep.tls is not None:
        plain = [e for e in endpoints if not e.startswith("tls/")]
        if plain:
            raise HostsError(f"{path}: with [tls] every endpoint must be tls/..., not {plain[0]}")
        certs = (path.parent / dep.tls.certs).absolute()
        dep = msgspec.structs.replace(dep, tls=msgspec.structs.replace(dep.tls, certs=str(certs)))
    elif any(e.startswith("tls/") for e in endpoints):
        raise HostsError(f"{path}: tls/ endpoints need a [tls] section (certs = DIR)")
    if dep.acl.per_vehicle:
        vague = [h.name for h in dep.hosts if "autopilot" in h.roles and not h.vehicles]
        if vague:
            raise HostsError(
                f"{path}: [acl] per_vehicle needs the vehicles of every autopilot host "
                f"(vehicles = [...]), missing on {', '.join(vague)}"
            )
    return dep


def options_for_host(
    opts: LaunchOptions, deployment: Deployment | None, host_name: str | None
) -> LaunchOptions:
    """``opts`` narrowed to one host's roles and endpoints."""
    if deployment is None or host_name is None:
        raise HostsError("--hosts FILE and --host NAME go together")
    host = deployment.host(host_name)
    return replace(
        opts,
        connect=(deployment.router,),
        listen=tuple(host.listen) or opts.listen,
        roles=tuple(host.roles),
        router="router" in host.roles,
        vehicles=tuple(host.vehicles) if host.vehicles is not None else None,
    )
