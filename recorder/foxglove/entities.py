"""The scene entities of the Foxglove channels: plume isosurfaces and filaments or puffs, and the
vehicles' bodies. See docs/recording.md, "Foxglove"."""

from __future__ import annotations

import math
from functools import cache
from typing import Any

import numpy as np
from foxglove import messages as fm

from recorder.foxglove.channels import (
    DEFAULT_VEHICLE_TYPE,
    PLUME_STATE_ALPHA,
    PLUME_STATE_MAX_SPHERES,
    PLUME_STATE_MIN_DIAMETER_M,
    VEHICLE_SCALE,
    WORLD_FRAME,
    colour,
    pose,
    stamp,
)
from swarmbus.messages import PlumeMesh, PlumeState
from swarmbus.vehicle_types import VehicleType, VehicleTypeError, load_vehicle_type
from swarmbus.view_feed import PLUME_COLOURS, plume_points, reading_colour


def isosurface_entity(
    index: int, level: float, mesh: PlumeMesh, ts: fm.Timestamp
) -> fm.SceneEntity | None:
    vertices = np.frombuffer(mesh.vertices_f32, dtype="<f4").reshape(-1, 3).astype(float)
    faces = np.frombuffer(mesh.faces_i32, dtype="<i4")
    if faces.size == 0:
        return None
    triangles = fm.TriangleListPrimitive(
        pose=pose(),
        points=[fm.Point3(x=x, y=y, z=z) for x, y, z in vertices.tolist()],
        color=colour(PLUME_COLOURS[index % len(PLUME_COLOURS)], alpha=0.18 + 0.12 * index),
        indices=faces.tolist(),
    )
    return fm.SceneEntity(
        timestamp=ts,
        frame_id=WORLD_FRAME,
        id=f"plume/level_{index}",
        metadata=[fm.KeyValuePair(key="level_g_m3", value=f"{level:g}")],
        triangles=[triangles],
    )


def plume_state_update(state: PlumeState, now_ns: int) -> fm.SceneUpdate:
    """A time-dependent plume's filaments or puffs (``field/state``) as one entity of spheres,
    each of diameter 2R (a filament's R, a puff's σy; at least
    ``PLUME_STATE_MIN_DIAMETER_M``), coloured by its peak density (∝ R⁻³: the message carries
    no masses, and one source's filaments or puffs all carry the same) on a log scale from the
    frame's most diluted (blue) to its densest (red). One entity id, so each frame replaces
    the last; above ``PLUME_STATE_MAX_SPHERES`` every k-th is drawn (they are in release
    order)."""
    centres, radii = plume_points(state)  # a garbled sample draws what is whole of it
    stride = max(1, math.ceil(len(radii) / PLUME_STATE_MAX_SPHERES))
    centres, radii = centres[::stride], radii[::stride]
    diameters = np.maximum(2.0 * radii, PLUME_STATE_MIN_DIAMETER_M)
    density = _log_relative_density(radii)
    spheres = [
        fm.SpherePrimitive(
            pose=pose(x, y, z),
            size=fm.Vector3(x=d, y=d, z=d),
            color=colour(reading_colour(t, 1.0), alpha=PLUME_STATE_ALPHA),
        )
        for (x, y, z), d, t in zip(centres.tolist(), diameters.tolist(), density, strict=True)
    ]
    meta = {"model": state.model, "count": str(state.count), "drawn": str(len(spheres))}
    entity = fm.SceneEntity(
        timestamp=stamp(now_ns),
        frame_id=WORLD_FRAME,
        id="plume/state",
        metadata=[fm.KeyValuePair(key=k, value=v) for k, v in meta.items()],
        spheres=spheres,
    )
    return fm.SceneUpdate(entities=[entity])


def _log_relative_density(radii: np.ndarray[Any, np.dtype[np.float64]]) -> list[float]:
    """0 (the largest R) … 1 (the smallest) by log R: the log of R⁻³, rescaled."""
    log_r = np.log(np.maximum(radii, 1e-9))
    span = float(log_r.max() - log_r.min()) if radii.size else 0.0
    if not span > 0.0:  # one size (or none, or NaN): all dense
        return [1.0] * radii.size
    out: list[float] = ((log_r.max() - log_r) / span).tolist()
    return out


@cache
def vehicle_type(name: str) -> VehicleType:
    try:
        return load_vehicle_type(name)
    except VehicleTypeError:
        return load_vehicle_type(DEFAULT_VEHICLE_TYPE)


def body_entity(vid: str, vt: VehicleType, rgb: int, ts: fm.Timestamp) -> fm.SceneEntity:
    s = VEHICLE_SCALE
    hx, hy, hz = vt.collision_half_extents_m
    arm_r = max((math.hypot(r.position_m[0], r.position_m[1]) for r in vt.rotors), default=0.0)
    disc_d = 2 * max(0.05, 0.45 * arm_r) * s
    rotors = [
        fm.CylinderPrimitive(
            pose=pose(r.position_m[0] * s, r.position_m[1] * s, r.position_m[2] * s),
            size=fm.Vector3(x=disc_d, y=disc_d, z=0.02 * s),
            bottom_scale=1.0,
            top_scale=1.0,
            color=colour(rgb, alpha=0.6),
        )
        for r in vt.rotors
    ]
    return fm.SceneEntity(
        timestamp=ts,
        frame_id=vid,
        id=f"vehicle/{vid}",
        frame_locked=True,
        cubes=[
            fm.CubePrimitive(
                pose=pose(),
                size=fm.Vector3(x=2 * hx * s, y=2 * hy * s, z=2 * hz * s),
                color=colour(rgb),
            )
        ],
        cylinders=rotors,
        texts=[
            fm.TextPrimitive(
                pose=pose(0.0, 0.0, 2.0 * s * max(hz, 0.1) + 1.0),
                billboard=True,
                font_size=14.0,
                scale_invariant=True,
                color=colour(rgb),
                text=vid,
            )
        ],
    )
