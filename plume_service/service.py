"""``plumeswarm node plume``: the concentration field served on the bus.

Three queryables: ``plume/concentration`` (a batch of points → values in one reply),
``plume/info`` (model, parameters, sources, wind) and ``plume/mesh`` (isosurface at a level).
A malformed query gets an :class:`~swarmbus.messages.ErrorReply` naming the bad field, and the
service keeps serving.
"""

from __future__ import annotations

import logging
import queue
import threading
from collections.abc import Callable
from typing import TypeVar

import numpy as np
import zenoh

from plume_service.field import ConcentrationField
from plume_service.from_scenario import field_from_scenario
from plume_service.mesh import gaussian_sources, isosurface
from swarmbus.codec import MessageError, decode, encode
from swarmbus.messages import (
    ErrorReply,
    PlumeInfo,
    PlumeInfoQuery,
    PlumeMesh,
    PlumeMeshQuery,
    PlumeQuery,
    PlumeSource,
    PlumeValues,
)
from swarmbus.node import NodeContext, NodeRuntime

log = logging.getLogger(__name__)

#: Largest mesh grid served over the bus (points); finer requests are refused, not attempted.
MAX_MESH_GRID_POINTS = 20_000_000


class PlumeService:
    """Answers plume queries for one field; pure request → reply functions, bus-agnostic."""

    def __init__(self, field: ConcentrationField) -> None:
        self.field = field

    def concentration(self, query: PlumeQuery) -> PlumeValues:
        if not query.points_enu_m:
            return PlumeValues(values_g_m3=[], sim_time_s=query.sim_time_s)
        points = np.asarray(query.points_enu_m, dtype=np.float64)
        values = self.field.concentration(points, query.sim_time_s)
        return PlumeValues(values_g_m3=values.tolist(), sim_time_s=query.sim_time_s)

    def info(self, _query: PlumeInfoQuery) -> PlumeInfo:
        plumes = gaussian_sources(self.field)
        first = plumes[0]
        return PlumeInfo(
            model="gaussian",
            stability=first.stability,
            coefficients=first.coefficients,
            wind_speed_m_s=first.wind_speed_m_s,
            wind_from_deg=first.wind_from_deg,
            mixing_height_m=first.mixing_height_m,
            sources=[
                PlumeSource(
                    x_m=p.source_m[0],
                    y_m=p.source_m[1],
                    release_rate_g_s=p.release_rate_g_s,
                    release_height_m=p.release_height_m,
                )
                for p in plumes
            ],
        )

    def mesh(self, query: PlumeMeshQuery) -> PlumeMesh:
        bounds = None
        if query.bounds_min_m is not None and query.bounds_max_m is not None:
            lo, hi = query.bounds_min_m, query.bounds_max_m
            if any(h <= lo_ for lo_, h in zip(lo, hi, strict=True)):
                raise ValueError("bounds_max_m must exceed bounds_min_m on every axis")
            bounds = ((lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]))
        if bounds is not None:
            cells = np.prod([(b[1] - b[0]) / query.resolution_m + 1 for b in bounds])
            if cells > MAX_MESH_GRID_POINTS:
                raise ValueError(
                    f"grid of {cells:.3g} points exceeds {MAX_MESH_GRID_POINTS}; "
                    "use a coarser resolution_m"
                )
        vertices, faces = isosurface(self.field, query.level_g_m3, bounds, query.resolution_m)
        return PlumeMesh(
            level_g_m3=query.level_g_m3,
            vertices_f32=np.asarray(vertices, dtype="<f4").tobytes(),
            faces_i32=np.asarray(faces, dtype="<i4").tobytes(),
        )


Q = TypeVar("Q")
R = TypeVar("R")


def _handler(
    query_type: type[Q], serve: Callable[[Q], R], what: str, memo: bool = False
) -> Callable[[zenoh.Query], None]:
    """``memo``: answer a payload equal to the previous one with the previous reply (in lockstep
    every autopilot asks for the same tick's positions: one computation serves them all)."""
    last: list[tuple[bytes, bytes]] = []  # at most one (payload, reply); replaced atomically

    def handle(query: zenoh.Query) -> None:
        payload = query.payload
        data = payload.to_bytes() if payload is not None else b""
        if memo and last and last[0][0] == data:
            query.reply(query.key_expr, last[0][1])
            return
        try:
            request = decode(data, query_type)
        except MessageError as exc:
            log.warning("plume %s: rejected query: %s", what, exc)
            query.reply_err(encode(ErrorReply(field=exc.field, reason=exc.reason[:1000])))
            return
        try:
            reply = serve(request)
        except ValueError as exc:
            log.warning("plume %s: cannot serve: %s", what, exc)
            query.reply_err(encode(ErrorReply(field="", reason=str(exc)[:1000])))
            return
        out = encode(reply)
        if memo:
            last[:] = [(data, out)]
        query.reply(query.key_expr, out)

    return handle


def main(ctx: NodeContext) -> int:
    """Serve the scenario's plume until stopped."""
    service = PlumeService(field_from_scenario(ctx.scenario))
    with NodeRuntime(ctx, role="plume") as rt:
        keys = rt.keys
        queryables = [
            rt.session.declare_queryable(
                keys.plume_concentration(),
                _handler(PlumeQuery, service.concentration, "concentration", memo=True),
            ),
            rt.session.declare_queryable(
                keys.plume_info(), _handler(PlumeInfoQuery, service.info, "info")
            ),
        ]
        # Meshes take seconds: queue them to their own thread so point queries never wait.
        # (A blocking recv() on a zenoh channel can't be interrupted by undeclare; a Python
        # queue with a timeout can.)
        mesh_queue: queue.Queue[zenoh.Query] = queue.Queue(maxsize=8)
        handle_mesh = _handler(PlumeMeshQuery, service.mesh, "mesh")

        def enqueue_mesh(query: zenoh.Query) -> None:
            try:
                mesh_queue.put_nowait(query)
            except queue.Full:
                query.reply_err(encode(ErrorReply(field="", reason="mesh queue full, retry later")))

        def mesh_worker() -> None:
            while not rt.stop.is_set():
                try:
                    query = mesh_queue.get(timeout=0.2)
                except queue.Empty:
                    continue
                handle_mesh(query)
                del query  # dropping the query finalises the reply

        queryables.append(rt.session.declare_queryable(keys.plume_mesh(), enqueue_mesh))
        worker = threading.Thread(target=mesh_worker, name="plume-mesh", daemon=True)
        worker.start()
        rt.ready()
        rt.stop.wait()
        worker.join(timeout=30.0)
        for q in queryables:
            q.undeclare()
    return 0
