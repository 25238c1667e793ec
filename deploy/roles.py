"""Which entry point runs each role (``plumeswarm node ROLE``).

Each entry is ``module:function`` with the signature ``main(ctx: NodeContext) -> int``; modules
are imported only when their role runs, so one role's dependencies never slow another's start.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable

from swarmbus.errors import PlumeswarmError
from swarmbus.node import NodeContext

RoleMain = Callable[[NodeContext], int]

ROLES: dict[str, str] = {
    "router": "deploy.router:main",
    "plume": "plume_service.service:main",
    "physics": "sim_world.physics_node:main",
    "autopilot": "agents.autopilot_node:main",
    "gateway": "gcs_bridge.gateway:main",
    "viewer": "sim_world.viewer:main",
    "recorder": "recorder.node:main",
    "foxglove": "recorder.foxglove.live:main",
    "ros2": "ros2_bridge.bridge:main",
}


# Stand-ins that take a role's place in ``plumeswarm bench scale --baseline`` (deploy.ceiling):
# the same processes doing no work but the lockstep handshake.
BENCH_ROLES: dict[str, str] = {
    "ceiling-physics": "deploy.ceiling:physics_main",
    "ceiling-autopilot": "deploy.ceiling:autopilot_main",
    "ceiling-plume": "deploy.ceiling:plume_main",
    "ceiling-gateway": "deploy.ceiling:gateway_main",
}


class RoleUnavailable(PlumeswarmError, RuntimeError):
    pass


def role_entry(role: str) -> RoleMain:
    """The ``main`` of ``role`` (or of a bench stand-in); :class:`RoleUnavailable` when the role
    is unknown or its package is not installed."""
    target = BENCH_ROLES.get(role) or ROLES.get(role)
    if target is None:
        raise RoleUnavailable(f"unknown role {role!r}; roles: {', '.join(ROLES)}")
    module_name, _, func_name = target.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name is not None and module_name.startswith(exc.name):
            raise RoleUnavailable(
                f"role {role!r}: its package {module_name} is not installed"
            ) from None
        raise
    func: RoleMain = getattr(module, func_name)
    return func
