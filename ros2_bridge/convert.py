"""Bus messages → ROS 2 messages (``rosbags``' classes of the distribution's definitions), and
a ``cmd_vel`` Twist → the vehicle's offboard ``Setpoint``. The bridge and ``export ros2`` both
convert through here.

Frames (REP-103, REP-105): the world is ``map``, ENU (x east, y north, z up) — the bus's world
frame; each vehicle's body is ``<vehicle>/base_link``, FLU (x forward, y left, z up) — the bus's
body frame. Stamps are sim time.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from ros2_bridge.wire import typestore
from swarmbus.messages import (
    AnemometerReading,
    ConcentrationReading,
    PlumeMesh,
    PlumeState,
    Setpoint,
    VehicleState,
)
from swarmbus.scenario import Scenario
from swarmbus.view_feed import PALETTE, PLUME_COLOURS, plume_points

WORLD_FRAME = "map"
CLOCK = "rosgraph_msgs/msg/Clock"
TF = "tf2_msgs/msg/TFMessage"
ODOM = "nav_msgs/msg/Odometry"
FIX = "sensor_msgs/msg/NavSatFix"
GAS = "sensor_msgs/msg/PointCloud"
WIND = "geometry_msgs/msg/Vector3Stamped"
MARKERS = "visualization_msgs/msg/MarkerArray"
TWIST = "geometry_msgs/msg/Twist"
GAS_CHANNELS = ("concentration_g_m3", "concentration_ppm", "true_concentration_g_m3")
MAX_FILAMENTS_DRAWN = 1000


def body_frame(vehicle_id: str) -> str:
    return f"{vehicle_id}/base_link"


def vehicle_topics(vehicle_id: str) -> dict[str, str]:
    """Each vehicle's topics → their types."""
    return {
        f"/{vehicle_id}/odom": ODOM,
        f"/{vehicle_id}/fix": FIX,
        f"/{vehicle_id}/gas": GAS,
        f"/{vehicle_id}/wind": WIND,
    }


def topics(vehicle_ids: Iterable[str]) -> dict[str, str]:
    """Every topic the bridge publishes (and ``export ros2`` writes) → its type."""
    out = {"/clock": CLOCK, "/tf": TF, "/plume/markers": MARKERS}
    for vid in vehicle_ids:
        out.update(vehicle_topics(vid))
    return out


def _t(name: str) -> Any:
    return typestore().types[name]


def stamp_ns(sim_time_s: float) -> int:
    return round(sim_time_s * 1e9)


def stamp(sim_time_s: float) -> Any:
    sec, nanosec = divmod(stamp_ns(sim_time_s), 1_000_000_000)
    return _t("builtin_interfaces/msg/Time")(sec=sec, nanosec=nanosec)


def header(sim_time_s: float, frame_id: str) -> Any:
    return _t("std_msgs/msg/Header")(stamp=stamp(sim_time_s), frame_id=frame_id)


def _vec(v: Sequence[float]) -> Any:
    return _t("geometry_msgs/msg/Vector3")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _point(v: Sequence[float]) -> Any:
    return _t("geometry_msgs/msg/Point")(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _quat(xyzw: Sequence[float]) -> Any:
    x, y, z, w = (float(c) for c in xyzw)
    return _t("geometry_msgs/msg/Quaternion")(x=x, y=y, z=z, w=w)


def rotation_matrix(xyzw: Sequence[float]) -> np.ndarray[Any, np.dtype[np.float64]]:
    """Body → world rotation of a unit quaternion (x, y, z, w)."""
    x, y, z, w = (float(c) for c in xyzw)
    n = math.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def yaw_rad(xyzw: Sequence[float]) -> float:
    """Heading of the body's x axis in the world (ENU: 0 = east, counter-clockwise)."""
    r = rotation_matrix(xyzw)
    return math.atan2(float(r[1, 0]), float(r[0, 0]))


def clock(sim_time_s: float) -> Any:
    return _t(CLOCK)(clock=stamp(sim_time_s))


def transform(state: VehicleState) -> Any:
    """``map`` → ``<vehicle>/base_link`` at the state's sim time."""
    return _t("geometry_msgs/msg/TransformStamped")(
        header=header(state.sim_time_s, WORLD_FRAME),
        child_frame_id=body_frame(state.vehicle_id),
        transform=_t("geometry_msgs/msg/Transform")(
            translation=_vec(state.position_enu_m), rotation=_quat(state.attitude_xyzw)
        ),
    )


def tf(states: Sequence[VehicleState]) -> Any:
    return _t(TF)(transforms=[transform(s) for s in states])


def odometry(state: VehicleState) -> Any:
    """Pose in ``map``; twist in the body frame (``child_frame_id``), as nav_msgs/Odometry says."""
    r = rotation_matrix(state.attitude_xyzw)
    v_body = r.T @ np.asarray(state.velocity_enu_m_s, dtype=float)
    zeros = np.zeros(36, dtype=np.float64)
    return _t(ODOM)(
        header=header(state.sim_time_s, WORLD_FRAME),
        child_frame_id=body_frame(state.vehicle_id),
        pose=_t("geometry_msgs/msg/PoseWithCovariance")(
            pose=_t("geometry_msgs/msg/Pose")(
                position=_point(state.position_enu_m), orientation=_quat(state.attitude_xyzw)
            ),
            covariance=zeros,
        ),
        twist=_t("geometry_msgs/msg/TwistWithCovariance")(
            twist=_t("geometry_msgs/msg/Twist")(
                linear=_vec(v_body), angular=_vec(state.body_rates_rad_s)
            ),
            covariance=zeros.copy(),
        ),
    )


def nav_sat_fix(state: VehicleState) -> Any:
    """The vehicle's true position as a GNSS fix (covariance unknown)."""
    status_t = _t("sensor_msgs/msg/NavSatStatus")
    return _t(FIX)(
        header=header(state.sim_time_s, body_frame(state.vehicle_id)),
        status=status_t(status=status_t.STATUS_FIX, service=status_t.SERVICE_GPS),
        latitude=state.lat_deg,
        longitude=state.lon_deg,
        altitude=state.alt_m,
        position_covariance=np.zeros(9, dtype=np.float64),
        position_covariance_type=_t(FIX).COVARIANCE_TYPE_UNKNOWN,
    )


def _or_nan(value: float | None) -> float:
    return math.nan if value is None else float(value)


def gas(reading: ConcentrationReading) -> Any:
    """One point at the sensor (the origin of ``<vehicle>/base_link``) with three channels:
    the reported concentration in g/m³, in ppm (NaN without a named gas) and the true one; NaN
    where the reading is unavailable."""
    channel_t = _t("sensor_msgs/msg/ChannelFloat32")
    values = (reading.reported_g_m3, reading.reported_ppm, reading.true_g_m3)
    return _t(GAS)(
        header=header(reading.sim_time_s, body_frame(reading.vehicle_id)),
        points=[_t("geometry_msgs/msg/Point32")(x=0.0, y=0.0, z=0.0)],
        channels=[
            channel_t(name=name, values=np.array([_or_nan(v)], dtype=np.float32))
            for name, v in zip(GAS_CHANNELS, values, strict=True)
        ],
    )


def wind(reading: AnemometerReading) -> Any:
    """The anemometer's (noisy) wind, ENU m/s, in ``map``."""
    return _t(WIND)(
        header=header(reading.sim_time_s, WORLD_FRAME), vector=_vec(reading.wind_enu_m_s)
    )


def _colour(rgb: int, alpha: float) -> Any:
    return _t("std_msgs/msg/ColorRGBA")(
        r=((rgb >> 16) & 0xFF) / 255.0,
        g=((rgb >> 8) & 0xFF) / 255.0,
        b=(rgb & 0xFF) / 255.0,
        a=alpha,
    )


def _marker(sim_time_s: float, ns: str, marker_id: int, kind: int, **fields: Any) -> Any:
    m = _t("visualization_msgs/msg/Marker")
    defaults: dict[str, Any] = {
        "header": header(sim_time_s, WORLD_FRAME),
        "ns": ns,
        "id": marker_id,
        "type": kind,
        "action": m.ADD,
        "pose": _t("geometry_msgs/msg/Pose")(
            position=_point((0, 0, 0)), orientation=_quat((0, 0, 0, 1))
        ),
        "scale": _vec((1.0, 1.0, 1.0)),
        "color": _colour(0xFFFFFF, 1.0),
        "lifetime": _t("builtin_interfaces/msg/Duration")(sec=0, nanosec=0),
        "frame_locked": False,
        "points": [],
        "colors": [],
        "texture_resource": "",
        "texture": _t("sensor_msgs/msg/CompressedImage")(
            header=header(sim_time_s, ""), format="", data=np.zeros(0, dtype=np.uint8)
        ),
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": _t("visualization_msgs/msg/MeshFile")(
            filename="", data=np.zeros(0, dtype=np.uint8)
        ),
        "mesh_use_embedded_materials": False,
    }
    defaults.update(fields)
    return m(**defaults)


def source_markers(scenario: Scenario, sim_time_s: float) -> list[Any]:
    m = _t("visualization_msgs/msg/Marker")
    return [
        _marker(
            sim_time_s,
            "source",
            i,
            m.SPHERE,
            pose=_t("geometry_msgs/msg/Pose")(
                position=_point((s.x_m, s.y_m, s.release_height_m)),
                orientation=_quat((0, 0, 0, 1)),
            ),
            color=_colour(0x000000, 1.0),
        )
        for i, s in enumerate(scenario.plume.sources)
    ]


def mesh_marker(mesh: PlumeMesh, index: int, sim_time_s: float) -> Any:
    """A ``plume/mesh`` isosurface as a translucent TRIANGLE_LIST (three points a face)."""
    vertices = np.frombuffer(mesh.vertices_f32, dtype="<f4").reshape(-1, 3).astype(np.float64)
    faces = np.frombuffer(mesh.faces_i32, dtype="<i4").reshape(-1, 3)
    faces = faces[(faces >= 0).all(axis=1) & (faces < len(vertices)).all(axis=1)]
    points = [_point(p) for p in vertices[faces.reshape(-1)]]
    colour = PLUME_COLOURS[index % len(PLUME_COLOURS)]
    return _marker(
        sim_time_s, "plume_isosurface", index, _t("visualization_msgs/msg/Marker").TRIANGLE_LIST,
        points=points, color=_colour(colour, 0.35),
        text=f"{mesh.level_g_m3:g} g/m3",
    )  # fmt: skip


def filament_marker(state: PlumeState) -> Any:
    """A filament or puff plume's centres as one SPHERE_LIST (diameter: the mean 2R)."""
    centres, radii = plume_points(state)
    step = max(1, math.ceil(len(centres) / MAX_FILAMENTS_DRAWN))
    centres, radii = centres[::step], radii[::step]
    size = max(0.2, 2.0 * float(radii.mean())) if len(radii) else 0.2
    return _marker(
        state.sim_time_s, "plume_state", 0, _t("visualization_msgs/msg/Marker").SPHERE_LIST,
        points=[_point(c) for c in centres], scale=_vec((size, size, size)),
        color=_colour(PLUME_COLOURS[0], 0.5), text=f"{state.model} {state.count}",
    )  # fmt: skip


def markers(
    scenario: Scenario,
    sim_time_s: float,
    meshes: Sequence[PlumeMesh] = (),
    state: PlumeState | None = None,
) -> Any:
    """``/plume/markers``: the sources, the isosurfaces of a Gaussian plume, the filaments or
    puffs of a time-dependent one."""
    out = source_markers(scenario, sim_time_s)
    out += [mesh_marker(mesh, i, sim_time_s) for i, mesh in enumerate(meshes)]
    if state is not None:
        out.append(filament_marker(state))
    return _t(MARKERS)(markers=out)


def vehicle_colour(index: int) -> int:
    return PALETTE[index % len(PALETTE)]


def setpoint_of(twist: Any, state: VehicleState) -> Setpoint:
    """A ``cmd_vel`` Twist in the vehicle's body frame (FLU; REP-103 ``base_link``) → an
    offboard velocity setpoint in ENU: the horizontal part turned by the vehicle's heading (the
    body's roll and pitch are ignored, as for a ground-referenced velocity), ``linear.z`` up,
    ``angular.z`` the yaw rate (counter-clockwise positive, in both frames)."""
    heading = yaw_rad(state.attitude_xyzw)
    c, s = math.cos(heading), math.sin(heading)
    vx, vy, vz = float(twist.linear.x), float(twist.linear.y), float(twist.linear.z)
    values = (vx, vy, vz, float(twist.angular.z))
    if not all(math.isfinite(v) for v in values):
        raise ValueError("cmd_vel: a component is not finite")
    return Setpoint(
        velocity_enu_m_s=(c * vx - s * vy, s * vx + c * vy, vz),
        yaw_rate_deg_s=max(-3600.0, min(3600.0, math.degrees(float(twist.angular.z)))),
    )
