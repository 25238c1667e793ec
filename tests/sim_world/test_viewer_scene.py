"""The viewer's scene logic against a recording stand-in for meshcat's Visualizer."""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pytest
import zenoh

with warnings.catch_warnings():
    # meshcat 0.3.2 imports pyzmq's deprecated zmq.eventloop.ioloop; not ours to fix.
    warnings.simplefilter("ignore", DeprecationWarning)
    from sim_world.viewer import (
        WORLD_ROOT,
        Scene,
        ViewerOptions,
        mesh_queries,
        pose_matrix,
    )
    from swarmbus.view_feed import Feed, default_levels, reading_colour, scene_bounds
from swarmbus.codec import encode
from swarmbus.messages import PlumeMesh, PlumeState, SimTick, VehicleState
from swarmbus.scenario import load_scenario, resolve_scenario_path
from swarmbus.vehicle_types import load_vehicle_type
from tests.support.messages_samples import reading, vehicle_state
from tests.support.procs import Network, keys_for, wait_until


class FakeNode:
    def __init__(self, vis: FakeVis, path: str) -> None:
        self.vis, self.path = vis, path

    def __getitem__(self, name: str) -> FakeNode:
        return FakeNode(self.vis, f"{self.path}/{name}")

    def set_object(self, geometry: Any, material: Any = None) -> None:
        self.vis.objects[self.path] = (geometry, material)

    def set_transform(self, matrix: Any) -> None:
        self.vis.transforms[self.path] = np.asarray(matrix)

    def set_property(self, key: str, value: Any) -> None:
        self.vis.properties[(self.path, key)] = value


class FakeVis:
    def __init__(self) -> None:
        self.objects: dict[str, Any] = {}
        self.transforms: dict[str, Any] = {}
        self.properties: dict[tuple[str, str], Any] = {}

    def __getitem__(self, path: str) -> FakeNode:
        return FakeNode(self, path)


def state(vid: str, tick: int, pos: tuple[float, float, float]) -> VehicleState:
    quarter_turn = (0.0, 0.0, math.sin(math.pi / 4), math.cos(math.pi / 4))
    return vehicle_state(vid, tick, pos, attitude_xyzw=quarter_turn)


@pytest.fixture
def scene() -> tuple[Scene, FakeVis]:
    vis = FakeVis()
    sc = Scene(vis, load_scenario(), ViewerOptions())
    sc.draw_static()
    return sc, vis


def test_static_scene_has_every_vehicle_with_its_rotors_and_the_source(
    scene: tuple[Scene, FakeVis],
) -> None:
    sc, vis = scene
    rotors = len(load_vehicle_type("iris").rotors)
    for vid in ("uav1", "uav2", "uav3"):
        assert f"/world/vehicles/{vid}/body" in vis.objects
        assert sum(p.startswith(f"/world/vehicles/{vid}/rotor_") for p in vis.objects) == rotors
    colours = {vis.objects[f"/world/vehicles/{v}/body"][1].color for v in ("uav1", "uav2", "uav3")}
    assert len(colours) == 3, "each vehicle in its own colour"
    assert "/world/source/0/release" in vis.objects and "/world/ground/grid" in vis.objects
    release = vis.transforms["/world/source/0/release"]
    assert release[:3, 3] == pytest.approx([0.0, 0.0, 10.0])
    assert {"/vehicles/uav1/body", "/source/0/release"} <= sc.paths


def test_states_pose_vehicles_and_grow_trails(scene: tuple[Scene, FakeVis]) -> None:
    sc, vis = scene
    for k in range(4):
        sc.update_states([state("uav1", k, (20.0 + k, 0.0, 10.0))], now_s=k * 1.0)
    m = vis.transforms["/world/vehicles/uav1"]
    assert m[:3, 3] == pytest.approx([23.0, 0.0, 10.0])
    # yaw 90°: body x points north; drawn vehicle_scale times larger
    assert m[:3, 0] == pytest.approx([0.0, 4.0, 0.0], abs=1e-9)
    trail = vis.objects["/world/trails/uav1"][0]
    assert trail.geometry.position.shape == (3, 4)


def test_readings_become_coloured_sized_markers(scene: tuple[Scene, FakeVis]) -> None:
    sc, vis = scene
    sc.update_states([state("uav2", 1, (30.0, 0.0, 10.0))], now_s=0.0)
    low = reading("uav2", 0.0, (30.0, 0.0, 10.0), 0.01)
    sc.update_reading(low)
    colour_low = vis.objects["/world/readings/uav2"][1].color
    size_low = vis.transforms["/world/readings/uav2"][0, 0]
    high = reading("uav2", 0.1, (30.0, 0.0, 10.0), 0.2)
    sc.update_reading(high)
    assert vis.objects["/world/readings/uav2"][1].color != colour_low
    assert vis.transforms["/world/readings/uav2"][0, 0] > size_low
    assert vis.transforms["/world/readings/uav2"][2, 3] > 10.0, "above the vehicle"


def test_plume_mesh_bytes_become_a_translucent_surface(scene: tuple[Scene, FakeVis]) -> None:
    sc, vis = scene
    verts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype="<f4")
    faces = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]], dtype="<i4")
    sc.set_plume(
        1, PlumeMesh(level_g_m3=0.05, vertices_f32=verts.tobytes(), faces_i32=faces.tobytes())
    )
    geometry, material = vis.objects["/world/plume/level_1"]
    assert geometry.vertices.shape == (4, 3) and geometry.faces.shape == (4, 3)
    assert material.transparent and 0 < material.opacity < 1
    empty = PlumeMesh(level_g_m3=0.5, vertices_f32=b"", faces_i32=b"")
    sc.set_plume(2, empty)
    assert "/world/plume/level_2" not in vis.objects


def test_pure_helpers() -> None:
    sc = load_scenario()
    assert default_levels(sc) == pytest.approx((0.01, math.sqrt(0.01 * 0.2), 0.2))
    lo, hi = scene_bounds(sc)
    assert lo[2] == 0.0 and lo[0] < 0.0 < 44.0 < hi[0] and lo[1] < -16.0 and hi[1] > 18.0
    assert reading_colour(0.0, 0.2) == 0x0000FF and reading_colour(1.0, 0.2) == 0xFF0000
    m = pose_matrix((1.0, 2.0, 3.0), (0.0, 0.0, 0.0, 1.0), 2.0)
    assert m[:3, 3] == pytest.approx([1, 2, 3]) and m[0, 0] == pytest.approx(2.0)


def test_feed_keeps_only_the_newest_tick(network: tuple[Network, zenoh.Session]) -> None:
    net, router = network
    keys = keys_for()
    from swarmbus.session import open_session

    def tick(k: int) -> bytes:
        return encode(SimTick(tick=k, sim_time_s=k / 120, control_dt_s=1 / 120, states=[]))

    with open_session(net.client) as session:
        feed = Feed(session, keys)

        def subscribed() -> bool:  # start-up handshake: the subscription reached the router
            router.put(keys.tick(), tick(0))
            return feed.take()[0] is not None

        wait_until(subscribed, 20.0, "the feed's subscription to carry a tick", poll_s=0.05)
        for k in range(1, 51):
            router.put(keys.tick(), tick(k))

        def newest() -> bool:
            raw, _ = feed.take()
            return raw is not None and raw == tick(50)

        wait_until(newest, 20.0, "tick 50 as the newest frame")
        assert feed.take()[0] is None, "a frame is handed out once; stale ones are dropped"
        feed.close()


def test_plume_state_becomes_a_point_cloud_and_filaments_ask_no_meshes(
    scene: tuple[Scene, FakeVis],
) -> None:
    sc, vis = scene
    centres = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]], dtype="<f4")
    radii = np.array([0.1, 0.3], dtype="<f4")
    sc.set_plume_state(
        PlumeState(
            sim_time_s=2.5,
            model="filament",
            count=2,
            centres_f32=centres.tobytes(),
            radii_f32=radii.tobytes(),
        )
    )
    geometry, _ = vis.objects[WORLD_ROOT + "/plume/state"]
    assert np.asarray(geometry.position).T.tolist() == centres.tolist()
    assert sc.plume_state_time_s == 2.5
    # A torn sample that still decodes (the bus is open): its whole rows, no exception.
    torn = PlumeState(
        sim_time_s=3.0,
        model="filament",
        count=2,
        centres_f32=centres.tobytes()[:20],  # one whole centre and two floats of the next
        radii_f32=radii.tobytes(),
    )
    sc.set_plume_state(torn)
    geometry, _ = vis.objects[WORLD_ROOT + "/plume/state"]
    assert np.asarray(geometry.position).T.tolist() == centres[:1].tolist()
    filament = load_scenario(resolve_scenario_path("filament"))
    assert mesh_queries(filament, ViewerOptions()) == []
    assert mesh_queries(load_scenario(), ViewerOptions())  # the Gaussian keeps its isosurfaces
