"""``plumeswarm node router``: a Zenoh router process (no separate router binary exists here)."""

from __future__ import annotations

import logging

import msgspec

from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import RoleOptions, role_main

log = logging.getLogger(__name__)


class RouterOptions(RoleOptions, frozen=True, kw_only=True):
    """The router takes no options (its endpoints are ``--listen``): any ``--set`` is refused."""


@role_main(RouterOptions, "router")
def main(ctx: NodeContext, options: RouterOptions) -> int:
    """Run a router on ``ctx.network.listen`` (default: the scenario's first connect endpoint)."""
    del options  # none are declared: an unknown one is refused
    net = ctx.network
    listen = [e for e in net.listen if not e.endswith(":0")] or list(net.connect)
    router_net = msgspec.structs.replace(net, mode="router", listen=listen, connect=[])
    ctx = NodeContext(ctx.scenario, router_net, ctx.name, ctx.vehicle_ids, ctx.options)
    with NodeRuntime(ctx, role="router") as rt:
        log.info("zenoh router listening on %s", ", ".join(listen))
        rt.ready()
        rt.stop.wait()
    return 0
