"""The pure World against closed-form physics (expected values never come from the code)."""

from __future__ import annotations

import math

import msgspec
import pymap3d
import pytest

from sim_world.world import GRAVITY_M_S2, World, wind_vector_enu
from swarmbus.scenario import Scenario, parse_scenario
from swarmbus.vehicle_types import VehicleType, load_vehicle_type

G = GRAVITY_M_S2
HZ = 240


def scenario(
    vehicles: list[tuple[str, str, tuple[float, float, float]]],
    wind_speed: float = 6.0,
    wind_from: float = 270.0,
    crash_speed: float = 3.0,
) -> Scenario:
    lines = [
        f"[time]\nphysics_hz = {HZ}\ncontrol_hz = 120\n",
        f"[wind]\nspeed_m_s = {wind_speed}\nfrom_deg = {wind_from}\n",
        f"[failsafe]\ncrash_speed_m_s = {crash_speed}\n",
    ]
    for vid, vtype, (x, y, z) in vehicles:
        lines.append(
            f'[[vehicles]]\nid = "{vid}"\ntype = "{vtype}"\nspawn_enu_m = [{x}, {y}, {z}]\n'
        )
    return parse_scenario("\n".join(lines))


def no_drag(name: str) -> VehicleType:
    return msgspec.structs.replace(load_vehicle_type(name), linear_drag_n_per_m_s=(0.0, 0.0, 0.0))


def hover_omega(vt: VehicleType) -> float:
    """Rotor speed at which n rotors carry the weight: n k_f w^2 = m g."""
    return math.sqrt(vt.mass_kg * G / (len(vt.rotors) * vt.thrust_coeff_n_per_rad2_s2))


def state(world: World, vid: str) -> object:
    return next(s for s in world.states(0) if s.vehicle_id == vid)


def z_of(world: World, vid: str) -> float:
    return next(s.position_enu_m[2] for s in world.states(0) if s.vehicle_id == vid)


def test_zero_thrust_from_rest_falls_half_g_t_squared() -> None:
    sc = scenario([("a", "iris", (0.0, 0.0, 100.0))])
    with World(sc, {"iris": no_drag("iris")}) as world:
        z0 = z_of(world, "a")
        world.step(HZ)  # 1 s
        drop = z0 - z_of(world, "a")
    t = 1.0
    assert drop == pytest.approx(G * t * t / 2.0, rel=0.01)


def test_fall_with_vertical_drag_follows_the_linear_drag_solution() -> None:
    sc = scenario([("a", "iris", (0.0, 0.0, 100.0))])
    vt = load_vehicle_type("iris")
    m, k = vt.mass_kg, vt.linear_drag_n_per_m_s[2]
    with World(sc) as world:
        z0 = z_of(world, "a")
        world.step(2 * HZ)
        drop = z0 - z_of(world, "a")
    t = 2.0
    expected = (m * G / k) * (t - (m / k) * (1.0 - math.exp(-k * t / m)))
    assert drop == pytest.approx(expected, rel=0.01)


def test_per_rotor_hover_thrust_holds_altitude_within_1_cm_for_5_s() -> None:
    sc = scenario([("a", "iris", (0.0, 0.0, 10.0))])
    vt = load_vehicle_type("iris")
    omega = hover_omega(vt)
    u = omega / vt.max_rotor_speed_rad_s
    with World(sc) as world:
        world.set_rotor_speeds("a", [omega] * 4)  # motors already spun up
        world.apply("a", [u] * 4)
        z0 = z_of(world, "a")
        worst = 0.0
        for _ in range(5 * 120):  # 5 s in control ticks of 2 substeps
            world.step(2)
            worst = max(worst, abs(z_of(world, "a") - z0))
    assert worst < 0.01


def test_motor_lag_is_first_order_with_the_type_time_constant() -> None:
    sc = scenario([("a", "iris", (0.0, 0.0, 0.0))])
    vt = load_vehicle_type("iris")
    tau = vt.motor_time_constant_s
    with World(sc) as world:
        world.apply("a", [0.5] * 4)
        steps = 6  # 25 ms = 2 tau at 240 Hz
        world.step(steps)
        omega = world.rotor_speeds("a")[0]
    target = 0.5 * vt.max_rotor_speed_rad_s
    assert omega == pytest.approx(target * (1.0 - math.exp(-steps / HZ / tau)), rel=1e-9)


def test_yaw_torque_turns_the_body_clockwise_at_the_rate_i_alpha_predicts() -> None:
    # Hexacopter: counter-clockwise rotors faster, clockwise slower, same total thrust, so the
    # only net torque is the reaction torque -k_m * sum(spin * w^2) (clockwise, negative z).
    sc = scenario([("h", "typhoon_h480", (0.0, 0.0, 50.0))])
    vt = load_vehicle_type("typhoon_h480")
    w2_hover = hover_omega(vt) ** 2
    delta = 0.2
    omegas = [math.sqrt(w2_hover * (1.0 + delta * r.spin)) for r in vt.rotors]
    torque_z = -sum(
        r.spin * vt.torque_coeff_nm_per_rad2_s2 * w * w
        for r, w in zip(vt.rotors, omegas, strict=True)
    )
    alpha = torque_z / vt.inertia_kg_m2[2]
    assert alpha < 0.0
    with World(sc) as world:
        world.set_rotor_speeds("h", omegas)
        world.step(HZ)  # 1 s
        (s,) = world.states(0)
    t = 1.0
    rate_z = s.body_rates_rad_s[2]
    assert rate_z == pytest.approx(alpha * t, rel=0.01)
    x, y, z, w = s.attitude_xyzw
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    assert yaw == pytest.approx(alpha * t * t / 2.0, rel=0.01)
    assert abs(s.body_rates_rad_s[0]) < 1e-6 and abs(s.body_rates_rad_s[1]) < 1e-6


@pytest.mark.parametrize("from_deg", [270.0, 45.0])
def test_in_steady_wind_a_free_body_drifts_to_the_wind_velocity(from_deg: float) -> None:
    speed = 6.0
    sc = scenario([("a", "iris", (0.0, 0.0, 30.0))], wind_speed=speed, wind_from=from_deg)
    vt = load_vehicle_type("iris")
    wind = wind_vector_enu(speed, from_deg)
    m, k = vt.mass_kg, vt.linear_drag_n_per_m_s[0]
    omega = hover_omega(vt)
    with World(sc) as world:
        world.set_rotor_speeds("a", [omega] * 4)
        world.step(int(m / k * HZ))  # one time constant: v = w (1 - 1/e)
        (s,) = world.states(0)
        for i in range(2):
            assert s.velocity_enu_m_s[i] == pytest.approx(wind[i] * (1 - math.exp(-1)), abs=0.01)
        world.step(int(6 * m / k * HZ) - int(m / k * HZ))  # six time constants
        (s,) = world.states(0)
    vx, vy, vz = s.velocity_enu_m_s
    assert math.hypot(vx - wind[0], vy - wind[1]) < 0.01 * speed
    assert abs(vz) < 0.01


def test_wind_from_west_blows_toward_east() -> None:
    assert wind_vector_enu(6.0, 270.0) == pytest.approx((6.0, 0.0, 0.0), abs=1e-12)
    assert wind_vector_enu(2.0, 0.0) == pytest.approx((0.0, -2.0, 0.0), abs=1e-12)


def test_geodetic_output_inverts_with_pymap3d_to_1_mm() -> None:
    spots = [(0.0, 0.0, 0.0), (812.5, -433.0, 57.0), (-2500.0, 1800.0, 300.0)]
    sc = scenario([(f"v{i}", "iris", p) for i, p in enumerate(spots)])
    o = sc.world.origin
    with World(sc) as world:
        world.step(3)
        for s in world.states(7, 0.5):
            e, n, u = pymap3d.geodetic2enu(
                s.lat_deg, s.lon_deg, s.alt_m, o.lat_deg, o.lon_deg, o.alt_m
            )
            assert math.dist((float(e), float(n), float(u)), s.position_enu_m) < 1e-3
            assert (s.tick, s.sim_time_s) == (7, 0.5)


def test_spawned_on_the_ground_is_landed_not_crashed() -> None:
    sc = scenario([("a", "iris", (3.0, 4.0, 0.0))])
    with World(sc) as world:
        (s,) = world.states(0)
        assert s.on_ground and not s.crashed
        # The collision box rests on the ground: its centre is half its height up.
        half_z = load_vehicle_type("iris").collision_half_extents_m[2]
        assert s.position_enu_m[2] == pytest.approx(half_z, abs=1e-3)
        world.step(HZ)
        (s,) = world.states(1)
        assert s.on_ground and not s.crashed


def test_hard_impact_crashes_soft_touchdown_lands() -> None:
    # From 5 m: impact at sqrt(2 g h) ≈ 9.9 m/s > 3 m/s; from 0.2 m: ≈ 2 m/s.
    sc = scenario([("hard", "iris", (0.0, 0.0, 5.0)), ("soft", "iris", (10.0, 0.0, 0.2))])
    with World(sc, {"iris": no_drag("iris")}) as world:
        for _ in range(2 * 120):
            world.step(2)
        states = {s.vehicle_id: s for s in world.states(0)}
    assert states["hard"].crashed and states["hard"].on_ground
    assert not states["soft"].crashed and states["soft"].on_ground


def test_vehicle_vehicle_contact_crashes_both_and_the_world_goes_on() -> None:
    sc = scenario([("below", "iris", (0.0, 0.0, 0.0)), ("above", "iris", (0.0, 0.0, 0.3))])
    with World(sc) as world:
        for _ in range(120):
            world.step(2)
        states = {s.vehicle_id: s for s in world.states(0)}
        assert states["below"].crashed and states["above"].crashed
        before = world.step_count
        world.step(2)
        assert world.step_count == before + 2


def test_commands_are_clamped_and_checked() -> None:
    sc = scenario([("a", "iris", (0.0, 0.0, 0.0))])
    vt = load_vehicle_type("iris")
    with World(sc, {"iris": msgspec.structs.replace(vt, motor_time_constant_s=0.0)}) as world:
        world.apply("a", [2.0, -1.0, 0.5, 1.0])
        world.step(1)
        omax = vt.max_rotor_speed_rad_s
        assert world.rotor_speeds("a") == pytest.approx((omax, 0.0, 0.5 * omax, omax))
        with pytest.raises(ValueError, match="4 rotors"):
            world.apply("a", [0.1] * 6)
        with pytest.raises(KeyError):
            world.apply("nope", [0.1] * 4)
        world.set_motors_enabled("a", False)
        world.apply("a", [1.0] * 4)
        world.step(1)
        assert world.rotor_speeds("a") == (0.0, 0.0, 0.0, 0.0)
        assert not world.states(0)[0].motors_enabled


def test_same_inputs_give_bit_identical_states() -> None:
    def run() -> list[bytes]:
        sc = scenario([("a", "iris", (0.0, 0.0, 0.0)), ("b", "typhoon_h480", (3.0, 0.0, 2.0))])
        out = []
        with World(sc) as world:
            for k in range(60):
                world.apply("a", [0.62, 0.6, 0.61, 0.63])
                world.apply("b", [0.5 + 0.01 * (k % 3)] * 6)
                world.step(2)
                out.append(msgspec.msgpack.encode(world.states(k)))
        return out

    assert run() == run()


def test_reading_states_between_steps_does_not_change_the_trajectory() -> None:
    def run(read_every_tick: bool) -> bytes:
        sc = scenario([("a", "iris", (0.0, 0.0, 1.0))])
        with World(sc) as world:
            for k in range(120):
                world.apply("a", [0.6 + 0.001 * (k % 7), 0.6, 0.61, 0.6])
                world.step(2)
                if read_every_tick:
                    world.states(k)
            return msgspec.msgpack.encode(world.states(0))

    assert run(True) == run(False)


def test_scalar_geodetic_matches_pymap3d() -> None:
    from sim_world.geodesy import EnuToGeodetic

    origin = (47.397742, 8.545594, 488.0)
    to_geodetic = EnuToGeodetic(*origin)
    for e, n, u in [(0.0, 0.0, 0.0), (123.4, -56.7, 10.0), (-480.0, 499.0, 150.0), (3, 4, -2)]:
        lat, lon, alt = pymap3d.enu2geodetic(e, n, u, *origin)
        got = to_geodetic(e, n, u)
        assert got[0] == pytest.approx(float(lat), abs=1e-12)
        assert got[1] == pytest.approx(float(lon), abs=1e-12)
        assert got[2] == pytest.approx(float(alt), abs=1e-7)
