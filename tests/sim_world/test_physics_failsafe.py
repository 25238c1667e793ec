"""The physics' realtime failsafe (sim_world.failsafe): a vehicle without commands descends
level at ``failsafe.descend_speed_m_s`` in the real World (pybullet) and lands without a crash;
the ticks without a command are counted. Expected values come from the setpoint and kinematics
(time to descend h at v is h / v), never from the controller."""

from __future__ import annotations

import logging
import math

import pytest

from sim_world.failsafe import VELOCITY_XY_P, CommandGaps, LandController
from sim_world.world import World
from swarmbus.messages import VehicleState
from swarmbus.scenario import Scenario, parse_scenario
from swarmbus.vehicle_types import load_vehicle_type

CONTROL_HZ = 120
SUBSTEPS = 2  # physics_hz 240


def scenario(z_m: float, wind_m_s: float = 1e-9, vtype: str = "iris") -> Scenario:
    """Still air unless ``wind_m_s`` (the scenario's wind must be > 0)."""
    return parse_scenario(
        f"[time]\nphysics_hz = {CONTROL_HZ * SUBSTEPS}\ncontrol_hz = {CONTROL_HZ}\n"
        f"[wind]\nspeed_m_s = {wind_m_s}\nfrom_deg = 270.0\n"
        f'[[vehicles]]\nid = "a"\ntype = "{vtype}"\nspawn_enu_m = [0.0, 0.0, {z_m}]\n'
    )


def tilt_deg(s: VehicleState) -> float:
    x, y, _, _ = s.attitude_xyzw
    return math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (x * x + y * y)))))


def fly(world: World, ctl: LandController, seconds: float) -> list[VehicleState]:
    """The failsafe in the loop, one command per control tick; every tick's state."""
    out = []
    for _ in range(round(seconds * CONTROL_HZ)):
        s = world.states(0)[0]
        out.append(s)
        cmd = ctl.command(s)
        world.apply_tick({} if cmd is None else {"a": cmd})
        world.step(SUBSTEPS)
    return out


def kick(world: World, seconds: float) -> None:
    """Uneven rotors for a while: the body rolls, pitches and spins."""
    for _ in range(round(seconds * CONTROL_HZ)):
        world.apply_tick({"a": [0.9, 0.6, 0.75, 0.7]})
        world.step(SUBSTEPS)


@pytest.mark.parametrize("vtype", ["iris", "typhoon_h480"])
def test_a_vehicle_without_commands_descends_level_at_the_set_speed_and_lands(vtype: str) -> None:
    height_m, speed_m_s = 20.0, 0.7
    sc = scenario(height_m, vtype=vtype)
    ctl = LandController(load_vehicle_type(vtype), speed_m_s)
    with World(sc) as world:
        states = fly(world, ctl, height_m / speed_m_s + 8.0)
    t_s = [k / CONTROL_HZ for k in range(len(states))]
    # past the first 5 s (from rest to the descent), the speed is the setpoint's
    steady = [s for s, t in zip(states, t_s, strict=True) if t > 5.0 and s.position_enu_m[2] > 2.0]
    assert steady
    for s in steady:
        assert s.velocity_enu_m_s[2] == pytest.approx(-speed_m_s, abs=0.02)
        assert tilt_deg(s) < 0.5
    landed = next(k for k, s in enumerate(states) if s.on_ground)
    assert not any(s.crashed for s in states)
    # h / v, plus the second or so of accelerating from rest
    assert height_m / speed_m_s < t_s[landed] < height_m / speed_m_s + 3.0
    assert states[-1].on_ground and not states[-1].crashed
    assert ctl.command(states[-1]) is None  # motors off on the ground


def test_a_tumbling_vehicle_is_levelled_then_lands_without_a_crash() -> None:
    ctl = LandController(load_vehicle_type("iris"), 0.7)
    with World(scenario(30.0)) as world:
        kick(world, 0.15)
        start = world.states(0)[0]
        assert tilt_deg(start) > 10.0 and max(abs(r) for r in start.body_rates_rad_s) > 1.0
        states = fly(world, ctl, 60.0)
    assert max(tilt_deg(s) for s in states[3 * CONTROL_HZ :]) < 1.0  # level within 3 s
    assert max(abs(s.body_rates_rad_s[2]) for s in states[3 * CONTROL_HZ :]) < 0.05
    assert states[-1].on_ground and not any(s.crashed for s in states)


def test_in_wind_it_stops_over_the_ground_and_lands_without_a_crash() -> None:
    wind_m_s = 6.0
    vtype = load_vehicle_type("iris")
    ctl = LandController(vtype, 0.7)
    with World(scenario(15.0, wind_m_s=wind_m_s)) as world:
        states = fly(world, ctl, 35.0)
    airborne = [s for s in states if not s.on_ground]
    # the velocity loop's steady state against the level body's drag D (w - v) = m k v
    drag = vtype.linear_drag_n_per_m_s[0]
    drift = drag * wind_m_s / (vtype.mass_kg * VELOCITY_XY_P + drag)
    assert airborne[-1].velocity_enu_m_s[0] == pytest.approx(drift, abs=0.05)
    assert max(tilt_deg(s) for s in airborne[2 * CONTROL_HZ :]) < 6.0  # leaning into the wind
    assert states[-1].on_ground and not any(s.crashed for s in states)


def test_the_ticks_without_a_command_are_counted_per_outage(
    caplog: pytest.LogCaptureFixture,
) -> None:
    sc = parse_scenario(
        '[time]\nphysics_hz = 200\ncontrol_hz = 100\n[[vehicles]]\nid = "a"\n'
        '[[vehicles]]\nid = "b"\nspawn_enu_m = [5.0, 0.0, 0.0]\n'
    )
    gaps = CommandGaps(sc, ["a", "b"])
    cmd = [0.5] * 4
    with World(sc) as world, caplog.at_level(logging.WARNING):
        for tick in range(60):
            silent = 10 <= tick < 25 or 40 <= tick < 45  # a: 15 ticks, then 5
            commands = {"b": cmd} if silent else {"a": cmd, "b": cmd}
            filled = gaps.fill(tick, commands, world.states(tick))
            assert ("a" in filled) is not silent  # on the ground: motors off, not the land
    assert gaps.gaps["a"].ticks == 20 and gaps.gaps["a"].outages == 2
    assert gaps.gaps["a"].longest_ticks == 15 and gaps.gaps["b"].ticks == 0
    assert "a commanded again after 15 ticks without (0.15 s sim" in caplog.text
    assert gaps.note() == "ticks without a command: a 20 in 2"
    assert "a: 20 ticks (0.20 s sim) in 2 outage(s), the longest 0.15 s" in gaps.summary(60)


def test_a_vehicle_without_commands_holds_for_the_hold_time_then_lands() -> None:
    """PX4's COM_FAIL_ACT_T: the Hold before the failsafe action. Through CommandGaps (what the
    physics runs in every clock mode): for ``failsafe.hold_s`` the vehicle keeps its altitude,
    then it descends at the landing speed; expected times from the setpoints (h / v)."""
    height_m, hold_s, speed_m_s = 8.0, 2.0, 0.7
    sc = parse_scenario(
        f"[time]\nphysics_hz = {CONTROL_HZ * SUBSTEPS}\ncontrol_hz = {CONTROL_HZ}\n"
        "[wind]\nspeed_m_s = 1e-9\nfrom_deg = 270.0\n"
        f"[failsafe]\nhold_s = {hold_s}\ndescend_speed_m_s = {speed_m_s}\n"
        f'[[vehicles]]\nid = "a"\nspawn_enu_m = [0.0, 0.0, {height_m}]\n'
    )
    gaps = CommandGaps(sc, ["a"])
    states: list[VehicleState] = []
    with World(sc) as world:
        seconds = hold_s + height_m / speed_m_s + 4.0
        for tick in range(round(seconds * CONTROL_HZ)):
            s = world.states(tick)[0]
            states.append(s)
            world.apply_tick(gaps.fill(tick, {}, [s]))
            world.step(SUBSTEPS)
    held = states[round(0.5 * CONTROL_HZ) : round(hold_s * CONTROL_HZ)]
    # spawned with motors off, it sags a little before the hold catches it, then keeps it
    assert all(abs(s.position_enu_m[2] - height_m) < 0.3 for s in held)
    assert abs(held[-1].velocity_enu_m_s[2]) < 0.1
    descending = [s for s in states if s.sim_time_s > hold_s + 2.0 and not s.on_ground]
    assert descending, "it never descended after the hold"
    assert descending[-1].velocity_enu_m_s[2] == pytest.approx(-speed_m_s, abs=0.1)
    landed = next(s for s in states if s.on_ground and s.sim_time_s > hold_s)
    assert landed.sim_time_s == pytest.approx(hold_s + height_m / speed_m_s, abs=1.5)
    assert states[-1].on_ground and not any(s.crashed for s in states)
    assert gaps.gaps["a"].outages == 1
