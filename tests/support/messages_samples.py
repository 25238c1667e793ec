"""One valid example of every bus message (round-trip and fuzz tests), and the builders of a
vehicle's state, status and reading for tests (:func:`vehicle_state`, :func:`vehicle_status`,
:func:`reading`)."""

from __future__ import annotations

from plumeswarm.bench.codec import STATE as STATE  # the sample state, shared with the codec bench
from swarmbus import messages as m

Vec3 = tuple[float, float, float]
LEVEL_XYZW = (0.0, 0.0, 0.0, 1.0)


def vehicle_state(
    vehicle_id: str = "uav1",
    tick: int = 0,
    position_enu_m: Vec3 = (0.0, 0.0, 10.0),
    *,
    sim_time_s: float | None = None,
    control_hz: float = 120.0,
    velocity_enu_m_s: Vec3 = (0.0, 0.0, 0.0),
    attitude_xyzw: tuple[float, float, float, float] = LEVEL_XYZW,
    lat_deg: float = 47.0,
    lon_deg: float = 8.0,
    alt_m: float = 500.0,
    on_ground: bool = False,
) -> m.VehicleState:
    """A vehicle's state in the air, still and level unless told (``sim_time_s``: ``tick /
    control_hz`` unless given)."""
    return m.VehicleState(
        vehicle_id=vehicle_id,
        tick=tick,
        sim_time_s=tick / control_hz if sim_time_s is None else sim_time_s,
        position_enu_m=position_enu_m,
        velocity_enu_m_s=velocity_enu_m_s,
        attitude_xyzw=attitude_xyzw,
        body_rates_rad_s=(0.0, 0.0, 0.0),
        lat_deg=lat_deg,
        lon_deg=lon_deg,
        alt_m=alt_m,
        on_ground=on_ground,
    )


def vehicle_status(**fields: object) -> m.VehicleStatus:
    """uav1's status at 1 s, disarmed on the ground, with ``fields`` changed."""
    base: dict[str, object] = dict(
        vehicle_id="uav1", sim_time_s=1.0, mode=m.FlightMode.DISARMED, armed=False, landed=True
    )
    return m.VehicleStatus(**(base | fields))  # type: ignore[arg-type]


def reading(
    vehicle_id: str,
    sim_time_s: float,
    position_enu_m: Vec3,
    g_m3: float | None,
    peers: list[m.PeerReading] | None = None,
) -> m.ConcentrationReading:
    """A noiseless reading of ``g_m3`` (None: unavailable)."""
    return m.ConcentrationReading(
        vehicle_id=vehicle_id,
        sim_time_s=sim_time_s,
        position_enu_m=position_enu_m,
        available=g_m3 is not None,
        reported_g_m3=g_m3,
        true_g_m3=g_m3,
        peers=peers or [],
    )


ITEM = m.MissionItem(x=40.0, y=-4.0, z=10.0, acceptance_radius_m=1.0, hold_s=2.0)

SAMPLES: dict[type[m.Message], m.Message] = {
    m.Clock: m.Clock(
        tick=1, sim_time_s=0.1, mode=m.SpeedMode.LOCKSTEP, speed_factor=1.0, real_time_factor=20.0
    ),
    m.VehicleState: STATE,
    m.SimTick: m.SimTick(tick=42, sim_time_s=0.35, control_dt_s=1 / 120, states=[STATE]),
    m.ActuatorCommand: m.ActuatorCommand(
        vehicle_id="uav1", tick=42, rotor_commands=[0.5, 0.5, 0.5, 0.5]
    ),
    m.ActuatorBatch: m.ActuatorBatch(
        tick=42,
        commands=[
            m.ActuatorCommand(vehicle_id="uav1", tick=42, rotor_commands=[0.5, 0.5, 0.5, 0.5]),
            m.ActuatorCommand(vehicle_id="uav2", tick=42, rotor_commands=[0.0] * 6),
        ],
    ),
    m.VehicleStatus: m.VehicleStatus(
        vehicle_id="uav1", sim_time_s=1.0, mode=m.FlightMode.MISSION, armed=True, landed=False
    ),
    m.ConcentrationReading: m.ConcentrationReading(
        vehicle_id="uav1",
        sim_time_s=1.0,
        position_enu_m=(20.0, 0.0, 10.0),
        available=True,
        reported_g_m3=0.12,
        true_g_m3=0.12,
        peers=[m.PeerReading(vehicle_id="uav2", position_enu_m=(20.0, 4.0, 10.0), true_g_m3=0.05)],
    ),
    m.Arm: m.Arm(),
    m.Disarm: m.Disarm(force=True),
    m.Takeoff: m.Takeoff(altitude_m=10.0),
    m.Land: m.Land(),
    m.ReturnToLaunch: m.ReturnToLaunch(),
    m.Hold: m.Hold(),
    m.Goto: m.Goto(position_enu_m=(1.0, 2.0, 3.0), yaw_deg=90.0),
    m.SetMode: m.SetMode(mode=m.FlightMode.HOLD),
    m.MissionUpload: m.MissionUpload(
        items=[ITEM, m.MissionItem(command=m.MissionCommand.LAND, x=0, y=0, z=0)]
    ),
    m.MissionStart: m.MissionStart(start_index=1),
    m.MissionPause: m.MissionPause(),
    m.MissionClear: m.MissionClear(),
    m.MissionDownload: m.MissionDownload(),
    m.Setpoint: m.Setpoint(velocity_enu_m_s=(1.0, 0.0, 0.0)),
    m.GcsHeartbeat: m.GcsHeartbeat(),
    m.SetParam: m.SetParam(name="MIS_TAKEOFF_ALT", value=10.0),
    m.GetParams: m.GetParams(),
    m.GeofenceUpload: m.GeofenceUpload(
        zones=[
            m.FenceZone(polygon_enu_m=[(0.0, 0.0), (50.0, 0.0), (50.0, 50.0)]),
            m.FenceZone(inclusion=False, center_enu_m=(10.0, 10.0), radius_m=5.0),
        ]
    ),
    m.RallyUpload: m.RallyUpload(points_enu_m=[(40.0, 5.0, 0.0)]),
    m.Orbit: m.Orbit(center_enu_m=(30.0, 0.0, 10.0), radius_m=8.0, speed_m_s=-2.0),
    m.CommandReply: m.CommandReply(
        vehicle_id="uav1", accepted=False, code=m.RejectCode.DENIED, reason="armed in the air"
    ),
    m.PlumeQuery: m.PlumeQuery(points_enu_m=[(20.0, 0.0, 10.0), (30.0, 1.0, 9.0)], sim_time_s=2.0),
    m.PlumeValues: m.PlumeValues(values_g_m3=[0.1, 0.05]),
    m.PlumeInfo: m.PlumeInfo(
        model="gaussian",
        stability="D",
        coefficients="novak2018",
        wind_speed_m_s=6.0,
        wind_from_deg=270.0,
        mixing_height_m=None,
        sources=[m.PlumeSource(x_m=0, y_m=0, release_rate_g_s=10.0, release_height_m=10.0)],
    ),
    m.PlumeInfoQuery: m.PlumeInfoQuery(),
    m.PlumeState: m.PlumeState(
        sim_time_s=1.5, model="filament", count=1, centres_f32=b"\x00" * 12, radii_f32=b"\x00" * 4
    ),
    m.FieldSample: m.FieldSample(tick=24, sim_time_s=0.2, values_g_m3=[0.0, 0.031]),
    m.AnemometerReading: m.AnemometerReading(
        vehicle_id="uav1",
        sim_time_s=1.5,
        position_enu_m=(1.0, 2.0, 10.0),
        wind_enu_m_s=(6.1, -0.2, 0.05),
        true_wind_enu_m_s=(6.0, 0.0, 0.0),
    ),
    m.RadioBatch: m.RadioBatch(
        sender="uav2",
        tick=120,
        messages=[
            m.RadioMessage(
                index=2, kind="agents.behaviors.coop_surge_cast:Detection", payload=b"\x93\x01"
            )
        ],
    ),
    m.PlumeMeshQuery: m.PlumeMeshQuery(level_g_m3=0.05, resolution_m=0.5),
    m.PlumeMesh: m.PlumeMesh(level_g_m3=0.05, vertices_f32=b"\x00" * 36, faces_i32=b"\x00" * 12),
    m.ErrorReply: m.ErrorReply(field="points_enu_m[0][2]", reason="Expected `float` <= 1e9"),
    m.NodeHealth: m.NodeHealth(
        name="physics", role="physics", state=m.NodeState.READY, version="0.1.0", pid=123, host="h"
    ),
    m.StepRequest: m.StepRequest(client="clock-3f2a", ticks=120),
    m.StepReply: m.StepReply(tick=240, sim_time_s=2.0),
    m.RestartNotice: m.RestartNotice(
        node="autopilot-uav1", role="autopilot", restarting=True, returncode=-9, vehicles=["uav1"]
    ),
}
