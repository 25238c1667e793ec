"""Isosurface meshes: closed, on the level, inside the derived bounds, written as STL and OBJ."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from plume_service import GaussianPlume, PlumeField
from plume_service.mesh import default_bounds, isosurface, write_mesh

LEVEL = 0.01
RESOLUTION = 0.25


@pytest.fixture(scope="module")
def seed_mesh():
    plume = GaussianPlume.preset("novak2018")
    vertices, faces = isosurface(plume, LEVEL, resolution_m=RESOLUTION)
    return plume, vertices, faces


def assert_closed(vertices, faces):
    """Every edge is shared by exactly two faces."""
    assert len(faces) > 0
    assert faces.min() >= 0
    assert faces.max() < len(vertices)
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert set(counts.tolist()) == {2}


def test_isosurface_is_closed(seed_mesh):
    _, vertices, faces = seed_mesh
    assert len(faces) > 1000
    assert_closed(vertices, faces)


def assert_on_level(field, vertices, resolution):
    """Every vertex is within one grid step of the level: C over the 6-neighbour stencil
    v ± h·e_i brackets it (marching cubes interpolates linearly along grid edges)."""
    offsets = np.vstack([np.zeros(3), np.eye(3), -np.eye(3)]) * resolution
    stencil = np.stack([field.concentration(vertices + offset) for offset in offsets])
    assert np.all(stencil.min(axis=0) <= LEVEL)
    assert np.all(stencil.max(axis=0) >= LEVEL)
    # And most vertices are far closer than that.
    assert np.median(np.abs(stencil[0] / LEVEL - 1.0)) < 0.01


def test_vertices_lie_on_the_level(seed_mesh):
    plume, vertices, _ = seed_mesh
    assert_on_level(plume, vertices, RESOLUTION)


def test_mesh_spans_the_seed_window(seed_mesh):
    _, vertices, _ = seed_mesh
    # The centreline at z = 10 m drops to 0.01 g/m³ near x ≈ 50.2 m (the closed-form
    # Gaussian with the seed's coefficients).
    assert vertices[:, 0].max() == pytest.approx(50.2, abs=0.5)
    assert vertices[:, 0].min() >= 0.0


def test_normals_point_outward(seed_mesh):
    _, vertices, faces = seed_mesh
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    signed_volume = np.einsum("ij,ij->", a, np.cross(b, c)) / 6.0
    assert signed_volume > 0


@pytest.mark.parametrize("wind_from_deg", [270.0, 200.0])
def test_default_bounds_contain_the_level_set(wind_from_deg):
    plume = GaussianPlume(
        10.0, 4.0, 5.0, stability="B", wind_from_deg=wind_from_deg, source=(20.0, -10.0)
    )
    (x0, x1), (y0, y1), (z0, z1) = default_bounds(plume, LEVEL)
    rng = np.random.default_rng(5)
    span = np.array([x1 - x0, y1 - y0, z1 - z0])
    outer = rng.uniform(
        np.array([x0, y0, 0.0]) - span, np.array([x1, y1, z1]) + span, size=(200_000, 3)
    )
    outside = (
        (outer[:, 0] < x0)
        | (outer[:, 0] > x1)
        | (outer[:, 1] < y0)
        | (outer[:, 1] > y1)
        | (outer[:, 2] < z0)
        | (outer[:, 2] > z1)
    )
    values = plume.concentration(outer)
    assert values[~outside].max() >= LEVEL
    assert values[outside].max() < LEVEL


def test_superposed_sources_mesh_is_closed():
    field = PlumeField(
        [GaussianPlume(5.0, 6.0, 10.0), GaussianPlume(5.0, 6.0, 10.0, source=(0.0, 6.0))]
    )
    vertices, faces = isosurface(field, LEVEL, resolution_m=0.4)
    assert_closed(vertices, faces)
    assert_on_level(field, vertices, 0.4)


def test_mesh_of_a_grounded_plume_is_closed_and_capped_at_ground():
    plume = GaussianPlume(10.0, 2.0, 2.0, stability="B")
    vertices, faces = isosurface(plume, LEVEL, resolution_m=0.5)
    assert_closed(vertices, faces)
    assert vertices[:, 2].min() == 0.0
    on_level = vertices[vertices[:, 2] > 0.0]
    assert_on_level(plume, on_level, 0.5)


def test_explicit_bounds_and_bad_arguments():
    plume = GaussianPlume.preset("novak2018")
    bounds = ((0.0, 20.0), (-3.0, 3.0), (7.0, 13.0))
    vertices, _ = isosurface(plume, 0.1, bounds=bounds, resolution_m=0.5)
    assert vertices[:, 0].max() <= 20.5
    with pytest.raises(ValueError, match="level_g_m3"):
        isosurface(plume, 0.0, bounds=bounds)
    with pytest.raises(ValueError, match="resolution_m"):
        isosurface(plume, 0.1, bounds=bounds, resolution_m=-1.0)
    with pytest.raises(ValueError, match="exceeds"):
        isosurface(plume, 0.1, bounds=((0.0, 1e4), (0.0, 1e4), (0.0, 1e4)), resolution_m=1.0)


def test_write_stl_and_obj_round_trip(seed_mesh, tmp_path):
    _, vertices, faces = seed_mesh
    stl = write_mesh(tmp_path / "plume.stl", vertices, faces)
    data = stl.read_bytes()
    (count,) = struct.unpack_from("<I", data, 80)
    assert count == len(faces)
    assert len(data) == 84 + 50 * count
    record = np.dtype([("normal", "<f4", (3,)), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    triangles = np.frombuffer(data, dtype=record, offset=84)
    np.testing.assert_allclose(triangles["v"][7], vertices[faces[7]], rtol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(triangles["normal"], axis=1), 1.0, atol=1e-3)

    obj = write_mesh(tmp_path / "plume.obj", vertices, faces)
    lines = obj.read_text().splitlines()
    v_lines = [line for line in lines if line.startswith("v ")]
    f_lines = [line for line in lines if line.startswith("f ")]
    assert len(v_lines) == len(vertices)
    assert len(f_lines) == len(faces)
    assert [int(i) - 1 for i in f_lines[3].split()[1:]] == faces[3].tolist()

    with pytest.raises(ValueError, match=r"\.stl or \.obj"):
        write_mesh(tmp_path / "plume.ply", vertices, faces)
