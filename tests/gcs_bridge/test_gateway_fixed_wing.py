"""A fixed wing on MAVLink, raw pymavlink over UDP against the real stack (plume + physics +
autopilots + gateway): an Aerosonde (sysid 1) beside an Iris (sysid 2). Its heartbeat says
MAV_TYPE_FIXED_WING with PX4's modes, its parameters are the vehicle type's
``[fixed_wing.params]`` (read from the TOML file here, not from the code), a FW_AIRSPD_MIN
below the stall speed is refused with a STATUSTEXT, and the FW_AIRSPD_TRIM and NAV_LOITER_RAD
set by PARAM_SET are what it then flies: VFR_HUD airspeed at the new trim while its
groundspeed swings with the wind, on a circle of the new radius around the take-off point.
"""

from __future__ import annotations

import math
import statistics
import tomllib
from collections.abc import Iterator

import msgspec
import pytest

from gcs_bridge.dialect import Msg, mavlink
from swarmbus.session import free_udp_block
from swarmbus.vehicle_types import FixedWingParams
from tests.support.gateway_stack import gateway, vehicles
from tests.support.mavclient import MavClient
from tests.support.procs import REPO, zenoh_network

PLANE, QUAD = 1, 2
REAL32 = mavlink.MAV_PARAM_TYPE_REAL32
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED
NAN = float("nan")
TYPE_FILE = REPO / "swarmbus" / "vehicles" / "aerosonde.toml"
FW_PARAMS: dict[str, float] = tomllib.loads(TYPE_FILE.read_text())["fixed_wing"]["params"]
# the file's own note: C_L peaks at 1.63 → the Aerosonde stalls at 15.3 m/s in level flight
STALL_M_S = 15.3
WIND_M_S = 3.0  # from the west: toward +x (east), NED (0, +3, 0)
TRIM_M_S = 22.0  # set by PARAM_SET (the file says 25)
LOITER_M = 70.0  # set by PARAM_SET (the file says 100)
TAKEOFF_M = 30.0


def scenario_text(gcs_port: int, api_base: int) -> str:
    return f"""
[time]
physics_hz = 240
control_hz = 120
mode = "lockstep"
startup_timeout_s = 60.0

[wind]
speed_m_s = {WIND_M_S}
from_deg = 270.0

[failsafe]
takeoff_altitude_m = {TAKEOFF_M}

[gateway]
host = "127.0.0.1"
gcs_port = {gcs_port}
api_port_base = {api_base}
telemetry_hz = 4.0

[[vehicles]]
id = "p"
type = "aerosonde"
sysid = {PLANE}
spawn_enu_m = [0.0, 0.0, 0.0]
spawn_yaw_deg = 90.0

[[vehicles]]
id = "q"
type = "iris"
sysid = {QUAD}
spawn_enu_m = [-20.0, 0.0, 0.0]
"""


@pytest.fixture(scope="module")
def gcs(tmp_path_factory: pytest.TempPathFactory) -> Iterator[MavClient]:
    tmp = tmp_path_factory.mktemp("fixed_wing_gateway")
    gcs_port, api_base = free_udp_block(1), free_udp_block(2)
    scenario = tmp / "scenario.toml"
    scenario.write_text(scenario_text(gcs_port, api_base))
    with (
        zenoh_network() as (net, _router),
        vehicles(net, scenario, tmp, ["p", "q"], backend="real"),
        gateway(net, scenario, tmp, "cmd_timeout_s=3"),
        MavClient(gcs_port) as c,
    ):
        c.beat = True
        for sysid in (PLANE, QUAD):
            c.wait_standby(sysid)
        yield c


def modes(hb: Msg) -> tuple[int, int]:
    """PX4's (main, sub) mode: custom_mode's third and fourth bytes."""
    return (hb.custom_mode >> 16) & 0xFF, (hb.custom_mode >> 24) & 0xFF


def test_the_plane_says_fixed_wing_and_px4_modes(gcs: MavClient) -> None:
    plane = gcs.wait_type("HEARTBEAT", PLANE)
    quad = gcs.wait_type("HEARTBEAT", QUAD)
    assert plane.type == 1 == mavlink.MAV_TYPE_FIXED_WING
    assert quad.type == 2 == mavlink.MAV_TYPE_QUADROTOR
    assert plane.autopilot == quad.autopilot == mavlink.MAV_AUTOPILOT_PX4
    assert modes(plane) == modes(quad) == (4, 3)  # disarmed: AUTO / LOITER, as PX4 on the ground


def test_the_planes_parameters_are_its_types(gcs: MavClient) -> None:
    plane, quad = gcs.params(PLANE), gcs.params(QUAD)
    assert {count for _, _, count, _ in plane.values()} == {len(plane)}
    assert sorted(index for *_, index in plane.values()) == list(range(len(plane)))
    for name, value in FW_PARAMS.items():
        assert plane[name][0] == pytest.approx(value), name
        assert plane[name][1] == REAL32
    assert "MPC_XY_CRUISE" not in plane and "RTL_RETURN_ALT" in plane
    # the quad's without MPC_XY_CRUISE, and every field of the fixed-wing parameter schema
    assert len(plane) == len(quad) - 1 + len(msgspec.structs.fields(FixedWingParams)) == 56
    assert "MPC_XY_CRUISE" in quad and not any(n.startswith("FW_") for n in quad)


def test_below_stall_refused_then_trim_and_radius_are_flown(gcs: MavClient) -> None:
    c = gcs
    refused = c.param_set(PLANE, "FW_AIRSPD_MIN", STALL_M_S - 1.0, REAL32)
    assert refused.param_value == FW_PARAMS["FW_AIRSPD_MIN"]  # unchanged: refused
    c.until(
        "a STATUSTEXT about the stall",
        lambda: any("stall" in m.text for m in c.logged("STATUSTEXT", PLANE)),
        10.0,
    )
    assert c.param_set(PLANE, "FW_AIRSPD_MIN", STALL_M_S + 0.7, REAL32).param_value == (
        pytest.approx(STALL_M_S + 0.7)
    )
    assert c.param_set(PLANE, "FW_AIRSPD_TRIM", TRIM_M_S, REAL32).param_value == TRIM_M_S
    assert c.param_set(PLANE, "NAV_LOITER_RAD", LOITER_M, REAL32).param_value == LOITER_M
    c.send(PLANE, mavlink.MAVLink_param_request_read_message(PLANE, 1, b"FW_AIRSPD_TRIM", -1))
    assert c.wait_type("PARAM_VALUE", PLANE).param_value == TRIM_M_S

    # QGC's takeoff: NAV_TAKEOFF while disarmed (NaN altitude: MIS_TAKEOFF_ALT), then ARM
    assert c.command(PLANE, 22, -1, 0, 0, NAN, NAN, NAN, NAN) == ACCEPTED
    c.wait_mode(PLANE, 4, 2, armed=False)
    assert c.command(PLANE, 400, 1) == ACCEPTED
    c.wait_mode(PLANE, 4, 2, armed=True)
    c.wait_mode(PLANE, 4, 3, armed=True, timeout_s=120.0)  # at altitude: hold, a loiter

    # a full circle of the loiter, once settled: 2 pi 70 m / 22 m/s ≈ 20 s of sim time
    first = c.wait_type("GLOBAL_POSITION_INT", PLANE)
    c.until(
        "30 s of loitering",
        lambda: (
            c.logged("GLOBAL_POSITION_INT", PLANE)[-1].time_boot_ms > first.time_boot_ms + 30_000
        ),
        120.0,
    )
    mark = len(c.log)
    c.until(
        "a circle",
        lambda: (
            c.logged("GLOBAL_POSITION_INT", PLANE)[-1].time_boot_ms > first.time_boot_ms + 55_000
        ),
        120.0,
    )
    window = c.log[mark:]
    hud = [m for m in window if m.get_type() == "VFR_HUD" and m.get_srcSystem() == PLANE]
    local = [
        m for m in window if m.get_type() == "LOCAL_POSITION_NED" and m.get_srcSystem() == PLANE
    ]
    assert len(hud) > 20 and len(local) > 20
    airspeeds = [m.airspeed for m in hud]
    grounds = [m.groundspeed for m in hud]
    assert abs(statistics.median(airspeeds) - TRIM_M_S) < 1.0
    assert max(abs(a - TRIM_M_S) for a in airspeeds) < 2.5
    # downwind the ground speed is the airspeed plus the wind, upwind minus it
    assert max(grounds) - min(grounds) > WIND_M_S
    assert max(grounds) > TRIM_M_S + 0.5 * WIND_M_S > TRIM_M_S - 0.5 * WIND_M_S > min(grounds)
    assert all(abs(m.alt - hud[0].alt) < 3.0 for m in hud)  # level (AMSL, m)
    radii = [math.hypot(m.x, m.y) for m in local]  # took off from the local origin
    assert min(radii) > LOITER_M - 15.0 and max(radii) < LOITER_M + 15.0
    assert all(abs(m.throttle) == 0 for m in hud)  # actuators are not on the bus
