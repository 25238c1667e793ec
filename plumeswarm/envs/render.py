"""Drawing an environment: a top-down frame (``rgb_array``) or the meshcat viewer (``human``).

The frame is the plume's concentration at the mean start altitude (log colour scale, computed
once), the sources, and each vehicle with its latest reading, drawn with matplotlib off screen.
``human`` opens the same meshcat scene as ``plumeswarm up``'s viewer, served from this process
on 127.0.0.1 (its address is logged once).
"""

from __future__ import annotations

import logging
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np
import numpy.typing as npt
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from plume_service.from_scenario import field_from_scenario
from plume_service.service import PlumeService
from swarmbus.messages import ConcentrationReading, PlumeMeshQuery, VehicleState
from swarmbus.scenario import Scenario

if TYPE_CHECKING:
    from sim_world.viewer import MeshcatServer, Scene

log = logging.getLogger(__name__)

FRAME_PX = 480
GRID_POINTS = 160


class Renderer:
    def __init__(self, scenario: Scenario, mode: str) -> None:
        self.scenario = scenario
        self.mode = mode
        env = scenario.env
        self.lo = np.array(
            [min(env.start_min_enu_m[0], *(s.x_m for s in scenario.plume.sources)) - 10.0,
             min(env.start_min_enu_m[1], *(s.y_m for s in scenario.plume.sources)) - 10.0]
        )  # fmt: skip
        self.hi = np.array(
            [max(env.start_max_enu_m[0], *(s.x_m for s in scenario.plume.sources)) + 10.0,
             max(env.start_max_enu_m[1], *(s.y_m for s in scenario.plume.sources)) + 10.0]
        )  # fmt: skip
        self._server: MeshcatServer | None = None
        self._scene: Scene | None = None
        self._vis: Any = None
        self._figure: Any = None
        if mode == "human":
            self._open_viewer()
        else:
            self._open_frame()

    # ------------------------------------------------------------------ rgb_array
    def _open_frame(self) -> None:
        env = self.scenario.env
        z = 0.5 * (env.start_min_enu_m[2] + env.start_max_enu_m[2])
        xs = np.linspace(self.lo[0], self.hi[0], GRID_POINTS)
        ys = np.linspace(self.lo[1], self.hi[1], GRID_POINTS)
        gx, gy = np.meshgrid(xs, ys)
        points = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z)])
        field = field_from_scenario(self.scenario)
        values = field.concentration(points, 0.0).reshape(gx.shape)
        sensor = self.scenario.sensor.resolved()
        floor = (sensor.detection_limit_g_m3 or 1e-3) / 10.0
        self._full_scale = sensor.saturation_g_m3 or float(values.max()) or 1.0
        self._figure = fig = Figure(figsize=(FRAME_PX / 100, FRAME_PX / 100), dpi=100)
        FigureCanvasAgg(fig)
        ax = self._axes = fig.add_axes((0.1, 0.1, 0.85, 0.85))
        ax.imshow(
            np.log10(np.maximum(values, floor)),
            origin="lower",
            extent=(self.lo[0], self.hi[0], self.lo[1], self.hi[1]),
            cmap="Greens",
            aspect="auto",
        )
        for s in self.scenario.plume.sources:
            ax.plot([s.x_m], [s.y_m], marker="*", color="black", markersize=14)
        ax.set_xlim(self.lo[0], self.hi[0])
        ax.set_ylim(self.lo[1], self.hi[1])
        ax.set_xlabel("east (m)")
        ax.set_ylabel("north (m)")
        self._dots = ax.scatter([], [], s=40, c=[], cmap="autumn_r", vmin=0.0, vmax=1.0)
        self._title = ax.set_title("")

    def _frame(
        self, states: Mapping[str, VehicleState], readings: Mapping[str, ConcentrationReading]
    ) -> npt.NDArray[np.uint8]:
        full = self._full_scale
        xy = np.array([s.position_enu_m[:2] for s in states.values()]).reshape(-1, 2)
        colour = [
            min(1.0, (readings[v].reported_g_m3 or 0.0) / full) if v in readings else 0.0
            for v in states
        ]
        self._dots.set_offsets(xy)
        self._dots.set_array(np.asarray(colour))
        t = next(iter(states.values())).sim_time_s if states else 0.0
        self._title.set_text(f"t = {t:.1f} s")
        canvas = self._figure.canvas
        canvas.draw()
        return np.asarray(canvas.buffer_rgba())[:, :, :3].copy()

    # ------------------------------------------------------------------ human
    def _open_viewer(self) -> None:
        # meshcat (through the viewer) only when asked for; meshcat 0.3.2 imports pyzmq's
        # deprecated zmq.eventloop.ioloop, which is not ours to fix.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            import meshcat

            from plumeswarm.envs.meshcat_window import Window as _Window
            from sim_world.viewer import MeshcatServer, Scene, ViewerOptions
            from swarmbus.view_feed import default_levels, scene_bounds

        self._server = MeshcatServer().__enter__()
        window = _Window(self._server.zmq_url, False, [])
        vis = self._vis = meshcat.Visualizer(window=window)
        self._scene = Scene(vis, self.scenario, ViewerOptions())
        self._scene.draw_static()
        service = PlumeService(field_from_scenario(self.scenario))
        lo, hi = scene_bounds(self.scenario)
        for index, level in enumerate(default_levels(self.scenario)):
            query = PlumeMeshQuery(
                level_g_m3=level, resolution_m=1.0, bounds_min_m=lo, bounds_max_m=hi
            )
            self._scene.set_plume(index, service.mesh(query))
        log.info("plumeswarm environment viewer: %s", self._server.web_url)

    @property
    def web_url(self) -> str | None:
        """The meshcat page of ``human`` (None for ``rgb_array``)."""
        return self._server.web_url if self._server is not None else None

    def draw(
        self, states: Mapping[str, VehicleState], readings: Mapping[str, ConcentrationReading]
    ) -> npt.NDArray[np.uint8] | None:
        if self._scene is not None:
            now = next(iter(states.values())).sim_time_s if states else 0.0
            self._scene.update_states(list(states.values()), now)
            for reading in readings.values():
                self._scene.update_reading(reading)
            return None
        return self._frame(states, readings)

    def close(self) -> None:
        if self._vis is not None:
            self._vis.window.zmq_socket.close(linger=0)
            self._vis = None
        if self._server is not None:
            self._server.__exit__(None, None, None)
            self._server = None
        self._figure = None
