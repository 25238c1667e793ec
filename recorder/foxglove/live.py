"""The ``foxglove`` role: the run's Foxglove channels, live, over the Foxglove WebSocket
protocol (the foxglove SDK's server) on 127.0.0.1 — open ``ws://127.0.0.1:PORT`` in Foxglove.

A subscriber only, like the viewer: Zenoh callbacks keep the newest tick and the newest reading
of each vehicle; a loop converts them at most ``rate_hz`` times a second with the same
conversion the recorder uses (:class:`~recorder.foxglove.scene.FoxgloveScene`), so a slow client
or a slow role drops frames and never slows the lockstep; a time-dependent plume's newest
``field/state`` is converted the same way. The vehicles' bodies and the plume are sent again
every ``static_period_s`` (with the newest filaments or puffs) for clients that connect
later.

Options (``--set KEY=VALUE``): ``port`` (8765, Foxglove's default; 0: any free port),
``rate_hz`` (20), ``static_period_s`` (2).
"""

from __future__ import annotations

import logging
import sys
import time
from typing import Annotated, TypeVar

import foxglove
import msgspec

from recorder.foxglove.channels import (
    Out,
    channel_schema,
    encode,
)
from recorder.foxglove.scene import (
    FoxgloveScene,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import RoleOptions, role_main
from swarmbus.view_feed import Feed, MeshFetcher, isosurface_queries

log = logging.getLogger(__name__)

HOST = "127.0.0.1"
DEFAULT_PORT = 8765
HEALTH_PERIOD_S = 1.0

T = TypeVar("T")


class LiveOptions(RoleOptions, frozen=True, kw_only=True):
    """The foxglove role's options (``--set KEY=VALUE``)."""

    port: Annotated[int, msgspec.Meta(ge=0, le=65535)] = DEFAULT_PORT  # 0: any free port
    rate_hz: Annotated[float, msgspec.Meta(ge=0.1, le=100.0)] = 20.0
    static_period_s: Annotated[float, msgspec.Meta(ge=0.1, le=3600.0)] = 2.0


class LiveChannels:
    """One SDK channel per Foxglove topic, made on first use, logging to ``context``."""

    def __init__(self, context: foxglove.Context) -> None:
        self._context = context
        self._channels: dict[str, foxglove.Channel] = {}
        self.sent = 0

    def log(self, out: Out) -> None:
        channel = self._channels.get(out.topic)
        if channel is None:
            cs = channel_schema(type(out.message))
            channel = foxglove.Channel(
                out.topic,
                schema=foxglove.Schema(name=cs.name, encoding=cs.encoding, data=cs.data),
                message_encoding=cs.message_encoding,
                context=self._context,
            )
            self._channels[out.topic] = channel
        channel.log(encode(out.message), log_time=out.log_time_ns)
        self.sent += 1


def convert(scene: FoxgloveScene, feed: Feed, meshes: MeshFetcher, channels: LiveChannels) -> int:
    """Feed what is new to ``scene`` and send what it makes; the newest tick, or -1."""
    now = time.time_ns()
    for mesh in meshes.take().values():
        for out in scene.feed(mesh, now):
            channels.log(out)
    fresh = feed.take_decoded()  # the plume state after the tick, which anchors the scene's clock
    messages: list[object | None] = [fresh.tick, *fresh.readings, fresh.plume_state]
    for message in messages:
        for out in scene.feed(message, now):
            channels.log(out)
    return -1 if fresh.tick is None else fresh.tick.tick


@role_main(LiveOptions, "foxglove")
def main(ctx: NodeContext, opts: LiveOptions) -> int:
    context = foxglove.Context()
    try:
        server = foxglove.start_server(
            name=f"plumeswarm {ctx.scenario.world.name}",
            host=HOST,
            port=opts.port,
            context=context,
        )
    except RuntimeError as exc:
        log.error(
            "foxglove: cannot serve on %s:%d (%s); another program uses the port? "
            "choose another with --set port=N",
            HOST,
            opts.port,
            exc,
        )
        return 2
    url = f"ws://{HOST}:{server.port}"
    try:
        with NodeRuntime(ctx, role="foxglove") as rt:
            scene = FoxgloveScene(ctx.scenario)
            channels = LiveChannels(context)
            feed = Feed(rt.session, rt.keys)
            meshes = MeshFetcher(rt.session, rt.keys, isosurface_queries(ctx.scenario))
            sys.stdout.write(f"foxglove: open {url} in Foxglove\n")  # this role's output
            sys.stdout.flush()
            rt.publish_health(detail=f"url={url} tick=-")
            rt.ready()
            next_health = next_static = time.monotonic()
            drawn = -1
            try:
                for t0 in rt.paced(opts.rate_hz):
                    drawn = max(drawn, convert(scene, feed, meshes, channels))
                    if t0 >= next_static:
                        next_static = t0 + opts.static_period_s
                        for out in scene.static_messages():
                            channels.log(out)
                    if t0 >= next_health:
                        next_health = t0 + HEALTH_PERIOD_S
                        rt.publish_health(
                            detail=f"url={url} tick={drawn if drawn >= 0 else '-'} "
                            f"sent={channels.sent}"
                        )
            finally:
                feed.close()
                meshes.close()
    finally:
        server.stop()
    return 0
