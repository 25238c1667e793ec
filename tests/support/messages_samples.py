"""One valid example of every bus message, for round-trip and fuzz tests."""

from __future__ import annotations

from swarmbus import messages as m

STATE = m.VehicleState(
    vehicle_id="uav1",
    tick=42,
    sim_time_s=0.35,
    position_enu_m=(20.0, -4.0, 10.0),
    velocity_enu_m_s=(1.0, 0.0, -0.1),
    attitude_xyzw=(0.0, 0.0, 0.0, 1.0),
    body_rates_rad_s=(0.01, -0.02, 0.0),
    lat_deg=47.397742,
    lon_deg=8.545859,
    alt_m=498.0,
    on_ground=False,
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
