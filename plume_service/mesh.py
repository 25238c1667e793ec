"""Isosurface meshes of a concentration field, and STL/OBJ writers.

The seed built its plume mesh with nested Python loops over a 0.1 m grid. Here the grid is
evaluated vectorised, slab by slab (bounded memory, optional tqdm progress bar), and the
surface is extracted by marching cubes from PyMCubes. The volume is padded with a layer of
zeros on every side, so the surface is closed even where the level set touches the domain
boundary (the cap lies on the boundary plane). Faces are oriented so their normals point
outward (toward lower concentration).

Default bounds for a Gaussian plume (or a superposition of them) are derived from the field:
first a conservative analytic box from C ≤ Q/(2π u σy)·(2/σz + √(2π)/L)·f(y), then tightened
by sampling the exact field in the plume's vertical plane (the crosswind factor separates),
with a margin so the level set is never cut.
"""

from __future__ import annotations

import logging
import math
import struct
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt
from tqdm import tqdm

from plume_service.field import ConcentrationField, FloatArray, PlumeField
from plume_service.gaussian import GaussianPlume

logger = logging.getLogger(__name__)

IntArray = npt.NDArray[np.int64]
#: ((x_min, x_max), (y_min, y_max), (z_min, z_max)) in world ENU metres.
Bounds = tuple[tuple[float, float], tuple[float, float], tuple[float, float]]

#: Grid points evaluated per slab of the volume.
SLAB_POINTS = 1 << 20
#: Refuse grids larger than this (a float64 volume of 3·10⁸ points is 2.4 GB).
MAX_GRID_POINTS = 300_000_000
# Samples of the exact field used to tighten default bounds, along x and z of the plume frame.
_SAMPLES_X = 768
_SAMPLES_Z = 384
# Relative margin added around the sampled extent.
_MARGIN = 0.05


def isosurface(
    field: ConcentrationField,
    level_g_m3: float,
    bounds: Bounds | None = None,
    resolution_m: float = 0.1,
    progress: bool = False,
    t: float | None = None,
) -> tuple[FloatArray, IntArray]:
    """Closed triangle mesh of the surface C = ``level_g_m3``.

    Returns ``(vertices, faces)``: (V, 3) float64 world ENU metres and (F, 3) int64 indices.
    ``bounds`` defaults to :func:`default_bounds`. Raises ValueError for a non-positive level
    or resolution, or a grid larger than :data:`MAX_GRID_POINTS`.
    """
    level = _positive("level_g_m3", level_g_m3)
    resolution = _positive("resolution_m", resolution_m)
    if bounds is None:
        bounds = default_bounds(field, level)
    axes = _grid_axes(bounds, resolution)
    padded = _evaluate_grid(field, axes, progress, t)
    import mcubes  # pulls in scipy.ndimage (≈ 0.7 s): loaded when a mesh is made

    vertices, faces = mcubes.marching_cubes(padded, level)
    origin = np.array([axis[0] for axis in axes]) - resolution
    vertices = np.asarray(vertices, dtype=np.float64) * resolution + origin
    # Where the level set reaches the domain's edge (the ground, say) the zero padding closes
    # it half a cell outside; put those cap vertices on the boundary plane instead.
    np.clip(vertices, [a[0] for a in axes], [a[-1] for a in axes], out=vertices)
    faces = np.asarray(faces, dtype=np.int64)
    if _signed_volume(vertices, faces) < 0.0:
        faces = np.ascontiguousarray(faces[:, ::-1])
    logger.info(
        "isosurface at %g g/m³: %d vertices, %d faces on a %s grid",
        level,
        len(vertices),
        len(faces),
        "×".join(str(len(axis)) for axis in axes),
    )
    return vertices, faces


def default_bounds(field: ConcentrationField, level_g_m3: float) -> Bounds:
    """A world box containing every point where ``field`` ≥ ``level_g_m3``.

    Supported for :class:`GaussianPlume` and :class:`PlumeField` of them; other fields need
    explicit bounds. For n superposed sources each is bounded at level/n, since a sum reaches
    the level only where some term reaches level/n.
    """
    level = _positive("level_g_m3", level_g_m3)
    plumes = gaussian_sources(field)
    if not plumes:
        raise ValueError(f"cannot derive bounds for {type(field).__name__}; pass bounds explicitly")
    boxes = [_plume_box(plume, level / len(plumes)) for plume in plumes]
    lows = np.min([[axis[0] for axis in box] for box in boxes], axis=0)
    highs = np.max([[axis[1] for axis in box] for box in boxes], axis=0)
    return (
        (float(lows[0]), float(highs[0])),
        (float(lows[1]), float(highs[1])),
        (float(lows[2]), float(highs[2])),
    )


def gaussian_sources(field: ConcentrationField) -> list[GaussianPlume]:
    """The Gaussian plumes a field is made of (itself, or the members of a PlumeField)."""
    if isinstance(field, GaussianPlume):
        return [field]
    if isinstance(field, PlumeField):
        return [plume for source in field.sources for plume in gaussian_sources(source)]
    return []


def write_mesh(path: str | Path, vertices: FloatArray, faces: IntArray) -> Path:
    """Write a mesh as binary STL (``.stl``) or Wavefront OBJ (``.obj``), chosen by suffix."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".stl":
        _write_stl(path, vertices, faces)
    elif suffix == ".obj":
        _write_obj(path, vertices, faces)
    else:
        raise ValueError(f"mesh path must end in .stl or .obj, got {str(path)!r}")
    logger.info("wrote %s (%d faces)", path, len(faces))
    return path


def _positive(name: str, value: float) -> float:
    number = float(value)
    if not math.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return number


def _grid_axes(bounds: Bounds, resolution: float) -> list[FloatArray]:
    axes = []
    for name, (low, high) in zip("xyz", bounds, strict=True):
        if not (math.isfinite(low) and math.isfinite(high) and high > low):
            raise ValueError(f"bounds for {name} must be finite with max > min, got {(low, high)}")
        count = math.ceil((high - low) / resolution) + 1
        axes.append(low + resolution * np.arange(count, dtype=np.float64))
    total = math.prod(len(axis) for axis in axes)
    if total > MAX_GRID_POINTS:
        raise ValueError(
            f"grid of {total} points exceeds {MAX_GRID_POINTS}; coarsen resolution_m "
            f"({resolution}) or shrink bounds"
        )
    return axes


def _evaluate_grid(
    field: ConcentrationField, axes: list[FloatArray], progress: bool, t: float | None
) -> FloatArray:
    """The field on the grid, inside one layer of zeros on every side (which closes the mesh);
    filled in place so the volume is never copied."""
    xs, ys, zs = axes
    padded = np.zeros((len(xs) + 2, len(ys) + 2, len(zs) + 2), dtype=np.float64)
    volume = padded[1:-1, 1:-1, 1:-1]
    plane = np.empty((len(ys), len(zs), 3), dtype=np.float64)
    plane[:, :, 1] = ys[:, None]
    plane[:, :, 2] = zs[None, :]
    per_slab = max(1, SLAB_POINTS // plane[:, :, 0].size)
    with tqdm(
        total=len(xs), desc="plume grid", unit="slice", disable=not progress, leave=False
    ) as bar:
        for start, stop in _slabs(len(xs), per_slab):
            slab = np.broadcast_to(plane, (stop - start, *plane.shape)).copy()
            slab[:, :, :, 0] = xs[start:stop, None, None]
            volume[start:stop] = field.concentration(slab.reshape(-1, 3), t).reshape(slab.shape[:3])
            bar.update(stop - start)
    return padded


def _slabs(count: int, size: int) -> Iterator[tuple[int, int]]:
    for start in range(0, count, size):
        yield start, min(start + size, count)


def _signed_volume(vertices: FloatArray, faces: IntArray) -> float:
    if len(faces) == 0:
        return 0.0
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0


def _plume_box(plume: GaussianPlume, level: float) -> Bounds:
    """World box around one plume's level set, from its plume-frame extent."""
    x_max, y_half, z_low, z_high = _plume_frame_extent(plume, level)
    ux, uy = plume.downwind_unit
    sx, sy = plume.source_m
    corners = np.array(
        [
            (sx + x * ux - y * uy, sy + x * uy + y * ux)
            for x in (0.0, x_max)
            for y in (-y_half, y_half)
        ]
    )
    low = corners.min(axis=0)
    high = corners.max(axis=0)
    return (float(low[0]), float(high[0])), (float(low[1]), float(high[1])), (z_low, z_high)


def _upper_bound(plume: GaussianPlume, x: FloatArray) -> FloatArray:
    """An upper bound on C(x, 0, z) over all z: Q/(2π u σy)·(2/σz + √(2π)/L)."""
    sigma_y, sigma_z = plume.sigmas(x)
    lid_term = (
        0.0 if plume.mixing_height_m is None else math.sqrt(2 * math.pi) / plume.mixing_height_m
    )
    rate = plume.release_rate_g_s / (2 * math.pi * plume.wind_speed_m_s)
    bound: FloatArray = rate / sigma_y * (2.0 / sigma_z + lid_term)
    return bound


def _plume_frame_extent(plume: GaussianPlume, level: float) -> tuple[float, float, float, float]:
    """(x_max, |y|_max, z_min, z_max) of {C ≥ level} in the plume frame, with a margin."""
    # Conservative box: the bound decreases with x because σy, σz are non-decreasing.
    far = np.geomspace(1e-3, 1e7, 4000)
    reach = far[_upper_bound(plume, far) >= level]
    if len(reach) == 0 or reach[-1] >= far[-1]:
        raise ValueError(f"level {level!r} g/m³ gives no bounded plume extent; pass bounds")
    x_bound = float(reach[-1]) * 1.01
    xs = np.linspace(x_bound / _SAMPLES_X, x_bound, _SAMPLES_X)
    _, sigma_z = plume.sigmas(xs)
    spread = np.sqrt(2.0 * np.log(np.maximum(_upper_bound(plume, xs) / level, 1.0)))
    z_bound = plume.release_height_m + float(np.max(sigma_z * spread)) * 1.01
    if plume.mixing_height_m is not None:
        z_bound = min(z_bound, plume.mixing_height_m)
    zs = np.linspace(0.0, z_bound, _SAMPLES_Z)
    # Exact centre-plane values C(x, 0, z) in world coordinates.
    ux, uy = plume.downwind_unit
    grid_x, grid_z = np.meshgrid(xs, zs, indexing="ij")
    points = np.column_stack(
        [
            plume.source_m[0] + grid_x.ravel() * ux,
            plume.source_m[1] + grid_x.ravel() * uy,
            grid_z.ravel(),
        ]
    )
    centre = plume.concentration(points).reshape(grid_x.shape)
    above = centre >= level
    if not above.any():
        # The level set is thinner than the sampling (a needle at the source): bound loosely.
        return x_bound, float(np.max(plume.sigmas(xs)[0] * spread)), 0.0, z_bound
    step_x = xs[1] - xs[0]
    step_z = zs[1] - zs[0]
    x_max = float(xs[above.any(axis=1)].max() + step_x) * (1 + _MARGIN)
    rows = above.any(axis=1)
    sigma_y, _ = plume.sigmas(xs)
    # |y| where C(x, y, z) = C(x, 0, z)·exp(−y²/2σy²) falls to the level.
    ratio = np.where(above, centre / level, 1.0).max(axis=1)
    y_half = float(np.max(sigma_y[rows] * np.sqrt(2.0 * np.log(ratio[rows]))))
    y_half = (y_half + step_x) * (1 + _MARGIN)
    z_rows = zs[above.any(axis=0)]
    z_low = max(0.0, float(z_rows.min()) - step_z - _MARGIN * (z_rows.max() - z_rows.min()))
    z_high = float(z_rows.max()) + step_z + _MARGIN * (z_rows.max() - z_rows.min())
    if plume.mixing_height_m is not None:
        z_high = min(z_high, plume.mixing_height_m)
    return x_max, y_half, z_low, z_high


def _write_stl(path: Path, vertices: FloatArray, faces: IntArray) -> None:
    triangles = vertices[faces].astype(np.float32)  # (F, 3, 3)
    normals = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    lengths = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = np.divide(normals, lengths, out=np.zeros_like(normals), where=lengths > 0)
    record = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
    data = np.zeros(len(faces), dtype=record)
    data["normal"] = normals
    data["vertices"] = triangles
    header = b"plumeswarm plume isosurface".ljust(80, b" ")
    with path.open("wb") as stream:
        stream.write(header)
        stream.write(struct.pack("<I", len(faces)))
        stream.write(data.tobytes())


def _write_obj(path: Path, vertices: FloatArray, faces: IntArray) -> None:
    with path.open("w", encoding="ascii") as stream:
        stream.write("# plumeswarm plume isosurface\n")
        np.savetxt(stream, vertices, fmt="v %.6f %.6f %.6f")
        np.savetxt(stream, faces + 1, fmt="f %d %d %d")
