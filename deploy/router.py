"""``plumeswarm node router``: a Zenoh router process (no separate router binary exists here)."""

from __future__ import annotations

import logging

import msgspec

from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import OptionError, RoleOptions, role_options

log = logging.getLogger(__name__)


class RouterOptions(RoleOptions, frozen=True, kw_only=True):
    """The router takes no options (its endpoints are ``--listen``): any ``--set`` is refused."""


def main(ctx: NodeContext) -> int:
    """Run a router on ``ctx.network.listen`` (default: the scenario's first connect endpoint)."""
    try:
        role_options(RouterOptions, ctx)
    except OptionError as exc:
        log.error("router: %s", exc)
        return 2
    net = ctx.network
    listen = [e for e in net.listen if not e.endswith(":0")] or list(net.connect)
    router_net = msgspec.structs.replace(net, mode="router", listen=listen, connect=[])
    ctx = NodeContext(ctx.scenario, router_net, ctx.name, ctx.vehicle_ids, ctx.options)
    with NodeRuntime(ctx, role="router") as rt:
        log.info("zenoh router listening on %s", ", ".join(listen))
        rt.ready()
        rt.stop.wait()
    return 0
