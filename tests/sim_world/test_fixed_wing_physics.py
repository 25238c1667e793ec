"""The fixed wing in the World against closed-form flight mechanics.

The trim is solved here from Beard & McLain's equations with the linear lift curve (a second
implementation, not the physics' code): flown open loop at that trim, the Aerosonde must keep
its altitude and airspeed, in still air and in a wind (only the air-relative velocity counts).
"""

from __future__ import annotations

import math

import pytest

from sim_world.world import GRAVITY_M_S2, World
from swarmbus.scenario import Scenario, parse_scenario
from swarmbus.vehicle_types import lift_coefficient, load_vehicle_type

G = GRAVITY_M_S2
HZ = 240
VT = load_vehicle_type("aerosonde")
FW = VT.fixed_wing
assert FW is not None


def scenario(wind_speed: float = 0.0, wind_from: float = 270.0) -> Scenario:
    wind_speed = max(wind_speed, 1e-9)  # the scenario wants a wind; 1e-9 m/s is still air
    return parse_scenario(
        f"[time]\nphysics_hz = {HZ}\ncontrol_hz = 120\n"
        f"[wind]\nspeed_m_s = {wind_speed}\nfrom_deg = {wind_from}\n"
        "[failsafe]\ncrash_speed_m_s = 3.0\n"
        '[[vehicles]]\nid = "p"\ntype = "aerosonde"\nspawn_enu_m = [0.0, 0.0, 0.0]\n'
    )


def trim(va: float) -> tuple[float, float, float]:
    """Level, wings-level trim at airspeed ``va``: (alpha, elevator rad, throttle)."""
    assert FW is not None
    m, rho, s = VT.mass_kg, FW.air_density_kg_m3, FW.wing_area_m2
    qbar = 0.5 * rho * va * va * s
    ar = FW.span_m**2 / s

    def elevator(alpha: float) -> float:  # pitching moment zero
        return -(FW.c_m_0 + FW.c_m_alpha * alpha) / FW.c_m_delta_e

    def normal(alpha: float) -> float:  # body z force (down positive) with theta = alpha
        cl = FW.c_l_0 + FW.c_l_alpha * alpha
        cd = FW.c_d_p + cl * cl / (math.pi * FW.oswald_e * ar)
        cz = -cd * math.sin(alpha) - cl * math.cos(alpha)
        czde = -FW.c_l_delta_e * math.cos(alpha)
        return m * G * math.cos(alpha) + qbar * (cz + czde * elevator(alpha))

    lo, hi = -0.2, 0.35
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if normal(mid) > 0.0 else (lo, mid)
    alpha = 0.5 * (lo + hi)
    de = elevator(alpha)
    cl = FW.c_l_0 + FW.c_l_alpha * alpha
    cd = FW.c_d_p + cl * cl / (math.pi * FW.oswald_e * ar)
    cx = -cd * math.cos(alpha) + cl * math.sin(alpha) + FW.c_l_delta_e * math.sin(alpha) * de
    prop = m * G * math.sin(alpha) - qbar * cx  # thrust needed along body x
    k = 0.5 * rho * FW.prop_area_m2 * FW.c_prop
    throttle = math.sqrt(prop / k + va * va) / FW.k_motor_m_s
    return alpha, de, throttle


def surface(rad: float, index: int) -> float:
    assert FW is not None
    return 0.5 + 0.5 * rad / math.radians(FW.max_deflection_deg[index])


@pytest.mark.parametrize(
    ("wind_speed", "yaw_deg"),
    [(0.0, 0.0), (3.0, 0.0), (3.0, 90.0)],
    ids=["still", "tailwind", "crosswind"],
)
def test_open_loop_trim_holds_altitude_and_airspeed(wind_speed: float, yaw_deg: float) -> None:
    va = 25.0
    alpha, de, throttle = trim(va)
    assert 0.0 < alpha < 0.2 and 0.0 < throttle < 1.0
    heading = (math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg)))
    # wind from 270°: air moving toward +x
    ground = (va * heading[0] + wind_speed, va * heading[1], 0.0)
    with World(scenario(wind_speed)) as world:
        world.set_motion("p", (0.0, 0.0, 100.0), ground, yaw_deg, math.degrees(alpha))
        world.set_rotor_speeds("p", [throttle, 0.5, surface(de, 1), 0.5])
        world.step(2 * HZ)
        s = world.states(0)[0]
    vx, vy, vz = s.velocity_enu_m_s
    airspeed = math.sqrt((vx - wind_speed) ** 2 + vy**2 + vz**2)
    assert s.position_enu_m[2] == pytest.approx(100.0, abs=0.3)
    assert airspeed == pytest.approx(va, abs=0.2)
    # 2 s of flight along the heading at the ground speed
    assert s.position_enu_m[0] == pytest.approx(2.0 * ground[0], abs=0.5)
    assert s.position_enu_m[1] == pytest.approx(2.0 * ground[1], abs=0.5)


def test_lift_curve_is_linear_below_stall_and_a_flat_plate_beyond() -> None:
    assert FW is not None
    for alpha in (-0.1, 0.0, 0.1, 0.2):
        assert lift_coefficient(FW, alpha) == pytest.approx(0.28 + 3.45 * alpha, rel=1e-3)
    for alpha in (0.7, 1.0, math.pi / 2):  # 2 sin^2 cos
        plate = 2.0 * math.sin(alpha) ** 2 * math.cos(alpha)
        assert lift_coefficient(FW, alpha) == pytest.approx(plate, abs=1e-3)
    peak = max(lift_coefficient(FW, a / 1000.0) for a in range(700))
    assert 1.4 < peak < 1.9  # the stall: no lift beyond this, so a minimum airspeed
    stall = math.sqrt(2 * VT.mass_kg * G / (FW.air_density_kg_m3 * FW.wing_area_m2 * peak))
    assert stall < FW.params.fw_airspd_min


@pytest.mark.parametrize(("sink", "crashed"), [(1.0, False), (4.0, True)])
def test_touchdown_is_a_crash_by_the_sink_rate_not_the_forward_speed(
    sink: float, crashed: bool
) -> None:
    half = VT.collision_half_extents_m[2]
    with World(scenario()) as world:
        world.set_motion("p", (0.0, 0.0, half + 0.2), (20.0, 0.0, -sink))
        for _ in range(60):  # control ticks of 2 substeps: contacts are checked per tick
            world.step(2)
        s = world.states(0)[0]
    assert s.on_ground
    assert s.crashed is crashed


def test_fixed_wing_takes_four_channels() -> None:
    with World(scenario()) as world:
        with pytest.raises(ValueError, match="4 rotors"):
            world.apply("p", [0.5] * 3)
        world.apply("p", [0.0, 0.5, 0.5, 0.5])
