"""The viewer role: a meshcat scene of the world, fed from the bus.

Ground grid, each vehicle as a body with rotor discs in its own colour, its trail, the plume
isosurfaces from ``plume/mesh`` as translucent surfaces (Gaussian plumes) or the filaments or
puffs of a time-dependent plume from ``field/state`` as a point cloud (each point a centre,
redrawn as states arrive), each vehicle's latest reading as a
coloured, sized marker above it, and the source marked. The meshcat server (its web files ship in
the package, nothing is fetched) runs on a thread of this process, on 127.0.0.1; the URL is
printed at start and published in this node's health ``detail``.

The viewer is only a subscriber: Zenoh callbacks store the newest payload and return; the render
loop decodes only the newest one at most ``rate_hz`` times a second, so a slow viewer drops frames
and never slows the lockstep.

Options (``--set KEY=VALUE``): ``http_port`` (0: any free), ``rate_hz`` (25), ``vehicle_scale``
(drawn size of the vehicles, 4: a 0.5 m quadcopter is invisible in a 60 m scene),
``levels`` (isosurface levels g/m³, comma-separated), ``mesh_resolution_m`` (1.0).
"""

from __future__ import annotations

import asyncio
import logging
import math
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any

import meshcat
import meshcat.geometry as mg
import meshcat.transformations as mtf
import msgspec
import numpy as np
from meshcat.servers.zmqserver import ZMQWebSocketBridge

from swarmbus.messages import (
    ConcentrationReading,
    PlumeMesh,
    PlumeMeshQuery,
    PlumeState,
    VehicleState,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import RoleOptions, role_main
from swarmbus.scenario import Scenario
from swarmbus.session import free_tcp_port
from swarmbus.vehicle_types import load_vehicle_type
from swarmbus.view_feed import (
    PALETTE,
    PLUME_COLOURS,
    READING_BINS,
    Feed,
    MeshFetcher,
    default_levels,
    isosurface_queries,
    plume_points,
    reading_colour,
    scene_bounds,
)

log = logging.getLogger(__name__)

TRAIL_PERIOD_S = 0.5
TRAIL_MAX_POINTS = 2000
WORLD_ROOT = "/world"
HEALTH_PERIOD_S = 1.0


class ViewerOptions(RoleOptions, frozen=True, kw_only=True):
    """The viewer role's options (``--set KEY=VALUE``)."""

    http_port: Annotated[int, msgspec.Meta(ge=0, le=65535)] = 0  # 0: any free port
    rate_hz: Annotated[float, msgspec.Meta(gt=0.0, le=25.0)] = 25.0
    vehicle_scale: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)] = 4.0
    levels_g_m3: tuple[Annotated[float, msgspec.Meta(gt=0.0)], ...] = msgspec.field(
        default=(), name="levels"
    )
    mesh_resolution_m: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)] = 1.0


def pose_matrix(position: Sequence[float], xyzw: Sequence[float], scale: float = 1.0) -> Any:
    x, y, z, w = xyzw
    m = mtf.quaternion_matrix([w, x, y, z])
    m[:3, :3] *= scale
    m[:3, 3] = position
    return m


class LoopbackBridge(ZMQWebSocketBridge):  # type: ignore[misc]
    """meshcat's bridge, but its web server listens on ``host`` only (meshcat's own binds every
    interface, whatever ``host`` says)."""

    http_server: Any = None

    def make_app(self) -> Any:
        app = super().make_app()
        plain_listen = app.listen
        host = self.host

        def listen(port: int, **kwargs: Any) -> Any:
            self.http_server = plain_listen(port, address=host, **kwargs)
            return self.http_server

        app.listen = listen
        return app

    def close(self) -> None:
        """Close its sockets (on its loop's thread, once the loop has stopped): a bridge inside
        a longer-lived process (an environment's viewer) must not leave them to the collector."""
        if self.http_server is not None:
            self.http_server.stop()
        for page in list(self.websocket_pool):  # browsers still connected
            page.close()
        self.zmq_stream.close(linger=0)
        self.ioloop.close(all_fds=False)  # tornado's loop, and the asyncio loop under it


class MeshcatServer:
    """meshcat's websocket/zmq bridge on a thread of this process (no orphan server process)."""

    def __init__(self, host: str = "127.0.0.1", http_port: int = 0) -> None:
        self.host = host
        self.http_port = http_port or free_tcp_port(host)
        self.zmq_url = f"tcp://{host}:{free_tcp_port(host)}"
        self._bridge: LoopbackBridge | None = None
        self._error: BaseException | None = None
        self._started = threading.Event()
        self._thread = threading.Thread(target=self._serve, name="meshcat", daemon=True)

    def _serve(self) -> None:
        loop = asyncio.new_event_loop()
        asyncio.set_event_loop(loop)
        try:
            self._bridge = LoopbackBridge(zmq_url=self.zmq_url, host=self.host, port=self.http_port)
        except BaseException as exc:
            self._error = exc
            self._started.set()
            return
        self._started.set()
        try:
            self._bridge.run()
        finally:
            self._bridge.close()

    @property
    def web_url(self) -> str:
        return f"http://{self.host}:{self.http_port}/static/"

    def __enter__(self) -> MeshcatServer:
        self._thread.start()
        if not self._started.wait(30.0) or self._error is not None:
            raise RuntimeError(f"meshcat server did not start: {self._error}")
        return self

    def __exit__(self, *exc: object) -> None:
        bridge = self._bridge
        if bridge is not None:
            bridge.ioloop.add_callback(bridge.ioloop.stop)
        self._thread.join(timeout=5.0)


@dataclass
class VehicleDrawing:
    colour: int
    trail: list[tuple[float, float, float]] = field(default_factory=list)
    last_trail_s: float = -1e9
    reading_bin: int | None = None
    position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    reading: float | None = None


class Scene:
    """What the viewer draws, and the set of scene paths it has set (for tests and tools)."""

    def __init__(self, vis: meshcat.Visualizer, scenario: Scenario, opts: ViewerOptions) -> None:
        self.vis = vis
        self.scenario = scenario
        self.opts = opts
        self.paths: set[str] = set()
        self.vehicles: dict[str, VehicleDrawing] = {}
        self.drawn_tick: int | None = None  # the newest tick drawn
        sensor = scenario.sensor.resolved()
        self.full_scale = sensor.saturation_g_m3 or max(default_levels(scenario))
        self.plume_state_time_s: float | None = None  # sim time of the drawn field/state

    def node(self, path: str) -> Any:
        """The scene node at ``path`` under the world root (which is shifted so that the
        orbit camera's fixed target, the origin, is the middle of the scene)."""
        return self.vis[WORLD_ROOT + path]

    def _set(self, path: str, geometry: Any, material: Any) -> None:
        self.node(path).set_object(geometry, material)
        self.paths.add(path)

    # ------------------------------------------------------------------ static
    def draw_static(self) -> None:
        lo, hi = scene_bounds(self.scenario)
        self.vis["/Grid"].set_property("visible", False)
        self._grid(lo, hi)
        for i, src in enumerate(self.scenario.plume.sources):
            base = f"/source/{i}"
            h = max(src.release_height_m, 0.1)
            self._set(
                f"{base}/stack",
                mg.Cylinder(h, 0.4),
                mg.MeshLambertMaterial(color=0x444444),
            )
            self.node(f"{base}/stack").set_transform(
                mtf.translation_matrix([src.x_m, src.y_m, h / 2])
                @ mtf.rotation_matrix(math.pi / 2, [1, 0, 0])
            )
            self._set(f"{base}/release", mg.Sphere(1.0), mg.MeshLambertMaterial(color=0xFF0000))
            self.node(f"{base}/release").set_transform(
                mtf.translation_matrix([src.x_m, src.y_m, src.release_height_m])
            )
        for i, v in enumerate(self.scenario.vehicles):
            self.draw_vehicle(v.id, v.type, PALETTE[i % len(PALETTE)], v.spawn_enu_m)
        self._camera(lo, hi)

    def _grid(self, lo: Sequence[float], hi: Sequence[float], step: float = 5.0) -> None:
        x0, x1 = math.floor(lo[0] / step) * step, math.ceil(hi[0] / step) * step
        y0, y1 = math.floor(lo[1] / step) * step, math.ceil(hi[1] / step) * step
        segs = []
        for x in np.arange(x0, x1 + step / 2, step):
            segs += [(x, y0, 0.0), (x, y1, 0.0)]
        for y in np.arange(y0, y1 + step / 2, step):
            segs += [(x0, y, 0.0), (x1, y, 0.0)]
        pts = np.array(segs, dtype=np.float32).T
        self.node("/ground/grid").set_object(
            mg.LineSegments(mg.PointsGeometry(pts), mg.LineBasicMaterial(color=0x888888))
        )
        self.paths.add("/ground/grid")

    def _camera(self, lo: Sequence[float], hi: Sequence[float]) -> None:
        centre = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 5.0]
        span = max(hi[0] - lo[0], hi[1] - lo[1])
        self.vis[WORLD_ROOT].set_transform(mtf.translation_matrix([-c for c in centre]))
        # The camera's position is in meshcat's Y-up "rotated" frame: (x, z, -y) of ENU.
        offset = (-0.25 * span, -0.55 * span, 0.35 * span)
        self.vis["/Cameras/default/rotated/<object>"].set_property(
            "position", [offset[0], offset[2], -offset[1]]
        )

    def draw_vehicle(
        self, vid: str, type_name: str, colour: int, position: Sequence[float]
    ) -> None:
        vt = load_vehicle_type(type_name)
        half = vt.collision_half_extents_m
        base = f"/vehicles/{vid}"
        body = mg.MeshLambertMaterial(color=colour)
        self._set(f"{base}/body", mg.Box([2 * half[0], 2 * half[1], 2 * half[2]]), body)
        arm_r = max((math.hypot(r.position_m[0], r.position_m[1]) for r in vt.rotors), default=0.0)
        disc_r = max(0.05, 0.45 * arm_r)
        for i, rotor in enumerate(vt.rotors):
            path = f"{base}/rotor_{i}"
            self._set(
                path,
                mg.Cylinder(0.02, disc_r),
                mg.MeshLambertMaterial(color=colour, opacity=0.6, transparent=True),
            )
            # Cylinders lie along y in meshcat: turn them into horizontal discs.
            self.node(path).set_transform(
                mtf.translation_matrix(rotor.position_m)
                @ mtf.rotation_matrix(math.pi / 2, [1, 0, 0])
            )
        self.vehicles[vid] = VehicleDrawing(colour=colour, position=tuple(position))  # type: ignore[arg-type]
        self.node(base).set_transform(pose_matrix(position, (0, 0, 0, 1), self.opts.vehicle_scale))

    # ------------------------------------------------------------------ dynamic
    def update_states(self, states: Sequence[VehicleState], now_s: float) -> None:
        for st in states:
            d = self.vehicles.get(st.vehicle_id)
            if d is None:
                self.draw_vehicle(
                    st.vehicle_id, "iris", PALETTE[len(self.vehicles) % len(PALETTE)], (0, 0, 0)
                )
                d = self.vehicles[st.vehicle_id]
            d.position = st.position_enu_m
            self.node(f"/vehicles/{st.vehicle_id}").set_transform(
                pose_matrix(st.position_enu_m, st.attitude_xyzw, self.opts.vehicle_scale)
            )
            if d.reading is not None:
                self._place_marker(st.vehicle_id, d)
            if now_s - d.last_trail_s >= TRAIL_PERIOD_S:
                d.last_trail_s = now_s
                if not d.trail or math.dist(d.trail[-1], st.position_enu_m) > 0.2:
                    d.trail.append(st.position_enu_m)
                    del d.trail[:-TRAIL_MAX_POINTS]
                    if len(d.trail) >= 2:
                        pts = np.array(d.trail, dtype=np.float32).T
                        path = f"/trails/{st.vehicle_id}"
                        self.node(path).set_object(
                            mg.Line(mg.PointsGeometry(pts), mg.LineBasicMaterial(color=d.colour))
                        )
                        self.paths.add(path)

    def update_reading(self, reading: ConcentrationReading) -> None:
        d = self.vehicles.get(reading.vehicle_id)
        if d is None or reading.reported_g_m3 is None:
            return
        d.reading = reading.reported_g_m3
        t = min(1.0, d.reading / self.full_scale) if self.full_scale > 0 else 0.0
        b = round(t * (READING_BINS - 1))
        path = f"/readings/{reading.vehicle_id}"
        if b != d.reading_bin:
            d.reading_bin = b
            self._set(
                path,
                mg.Sphere(1.0),
                mg.MeshLambertMaterial(color=reading_colour(d.reading, self.full_scale)),
            )
        self._place_marker(reading.vehicle_id, d)

    def _place_marker(self, vid: str, d: VehicleDrawing) -> None:
        if d.reading is None:
            return
        t = min(1.0, d.reading / self.full_scale) if self.full_scale > 0 else 0.0
        radius = 0.3 + 1.2 * t
        x, y, z = d.position
        m = mtf.translation_matrix([x, y, z + 1.5 + radius])
        m[:3, :3] *= radius
        self.node(f"/readings/{vid}").set_transform(m)

    def set_plume(self, index: int, mesh: PlumeMesh) -> None:
        vertices = np.frombuffer(mesh.vertices_f32, dtype="<f4").reshape(-1, 3)
        faces = np.frombuffer(mesh.faces_i32, dtype="<i4").reshape(-1, 3)
        path = f"/plume/level_{index}"
        if len(faces) == 0:
            log.info("plume isosurface at %g g/m3 is empty", mesh.level_g_m3)
            return
        colour = PLUME_COLOURS[index % len(PLUME_COLOURS)]
        self._set(
            path,
            mg.TriangularMeshGeometry(vertices.astype(np.float64), faces.astype(np.int64)),
            mg.MeshLambertMaterial(
                color=colour, opacity=0.18 + 0.12 * index, transparent=True, depthWrite=False
            ),
        )

    def set_plume_state(self, state: PlumeState) -> None:
        """Filament or puff centres as one point cloud, points sized by the mean radius."""
        centres, radii = plume_points(state)  # whole rows only: a torn sample draws fewer
        size = float(np.clip(2.0 * radii.mean(), 0.05, 5.0)) if radii.size else 0.1
        self._set(
            "/plume/state",
            mg.PointsGeometry(centres.T.astype(np.float32)),
            mg.PointsMaterial(size=size, color=0x8C33BF),
        )
        self.plume_state_time_s = state.sim_time_s


def mesh_queries(scenario: Scenario, opts: ViewerOptions) -> list[PlumeMeshQuery]:
    return isosurface_queries(scenario, opts.levels_g_m3, opts.mesh_resolution_m)


def render(scene: Scene, feed: Feed, meshes: MeshFetcher) -> int:
    """Draw what is new; the number of plume levels that arrived."""
    fresh = feed.take_decoded()
    if fresh.tick is not None:
        scene.update_states(fresh.tick.states, fresh.tick.sim_time_s)
        scene.drawn_tick = fresh.tick.tick
    for reading in fresh.readings:
        scene.update_reading(reading)
    if fresh.plume_state is not None:
        scene.set_plume_state(fresh.plume_state)
    new_meshes = meshes.take()
    for index, mesh in new_meshes.items():
        scene.set_plume(index, mesh)
    return len(new_meshes)


@role_main(ViewerOptions, "viewer")
def main(ctx: NodeContext, opts: ViewerOptions) -> int:
    with NodeRuntime(ctx, role="viewer") as rt, MeshcatServer(http_port=opts.http_port) as srv:
        vis = meshcat.Visualizer(zmq_url=srv.zmq_url)
        scene = Scene(vis, ctx.scenario, opts)
        scene.draw_static()
        feed = Feed(rt.session, rt.keys)
        meshes = MeshFetcher(rt.session, rt.keys, mesh_queries(ctx.scenario, opts))
        # The URL is this role's output for its user.
        sys.stdout.write(f"viewer: open {srv.web_url}\n")
        sys.stdout.flush()
        levels = len(meshes.queries)
        answered = 0
        rt.publish_health(detail=f"url={srv.web_url} plume=0/{levels}")
        rt.ready()
        next_health = time.monotonic() + HEALTH_PERIOD_S
        try:
            for t0 in rt.paced(opts.rate_hz):
                arrived = render(scene, feed, meshes)
                answered += arrived
                if arrived or t0 >= next_health:
                    # the newest drawn tick tells a supervisor (and a test) the scene is fed
                    next_health = t0 + HEALTH_PERIOD_S
                    rt.publish_health(
                        detail=f"url={srv.web_url} plume={answered}/{levels} "
                        f"tick={'-' if scene.drawn_tick is None else scene.drawn_tick}"
                    )
        finally:
            feed.close()
            meshes.close()
    return 0
