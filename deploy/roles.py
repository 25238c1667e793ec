"""Which entry point runs each role (``plumeswarm node ROLE``).

Each entry is ``module:function`` with the signature ``main(ctx: NodeContext) -> int``; modules
are imported only when their role runs, so one role's dependencies never slow another's start.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from swarmbus.node import NodeContext

RoleMain = Callable[[NodeContext], int]

ROLES: dict[str, tuple[str, str]] = {
    # role: (entry point, the issue that builds it)
    "router": ("deploy.router:main", "#7"),
    "plume": ("plume_service.service:main", "#3"),
    "physics": ("sim_world.physics_node:main", "#4"),
    "autopilot": ("agents.autopilot_node:main", "#5"),
    "gateway": ("gcs_bridge.gateway:main", "#6"),
    "viewer": ("sim_world.viewer:main", "#7"),
    "recorder": ("deploy.recorder:main", "#8"),
    "foxglove": ("deploy.foxglove.live:main", "#18"),
}


# Stand-ins that take a role's place in ``plumeswarm bench scale --baseline`` (deploy.ceiling):
# the same processes doing no work but the lockstep handshake.
BENCH_ROLES: dict[str, str] = {
    "ceiling-physics": "deploy.ceiling:physics_main",
    "ceiling-autopilot": "deploy.ceiling:autopilot_main",
    "ceiling-plume": "deploy.ceiling:plume_main",
    "ceiling-gateway": "deploy.ceiling:gateway_main",
}


class RoleUnavailable(RuntimeError):
    pass


def role_entry(role: str) -> RoleMain:
    """The ``main`` of ``role``; :class:`RoleUnavailable` when it is not built yet or unknown."""
    if role in BENCH_ROLES:
        module_name, _, func_name = BENCH_ROLES[role].partition(":")
        bench_main: RoleMain = getattr(importlib.import_module(module_name), func_name)
        return bench_main
    if role not in ROLES:
        raise RoleUnavailable(f"unknown role {role!r}; roles: {', '.join(ROLES)}")
    target, issue = ROLES[role]
    module_name, _, func_name = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.startswith(exc.name):
            raise RoleUnavailable(f"role {role!r} is not implemented yet (issue {issue})") from None
        raise
    func: RoleMain = getattr(module, func_name)
    return func
