"""One wind, three consumers: the physics' drag and the anemometer see the same air velocity at
the same tick; the anemometer's noise is its own, seeded per tick."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agents.anemometer import SEED_BLOCK, Anemometer, SeededNormals
from plume_atmosphere.wind import wind_from_scenario
from sim_world.world import GRAVITY_M_S2, World
from swarmbus.scenario import AnemometerSpec, parse_scenario
from swarmbus.vehicle_types import load_vehicle_type

MEANDER = """
[world]
seed = 4
[time]
physics_hz = 240
control_hz = 120
[wind]
speed_m_s = 3.0
model = "meander"
[wind.meander]
preset = "large"
[anemometer]
period_ticks = 1
noise_std_m_s = 0.1
[[vehicles]]
id = "a"
spawn_enu_m = [0.0, 0.0, 50.0]
"""


def test_a_hovering_body_follows_the_meandering_wind_through_its_drag() -> None:
    """With thrust = weight, dv/dt = (k/m)(w − v) with w held over each tick: expected v is that
    first-order filter of the wind series, written out here tick by tick."""
    scenario = parse_scenario(MEANDER)
    vt = load_vehicle_type("iris")
    omega = math.sqrt(vt.mass_kg * GRAVITY_M_S2 / (4 * vt.thrust_coeff_n_per_rad2_s2))
    rate = vt.linear_drag_n_per_m_s[0] / vt.mass_kg
    wind = wind_from_scenario(scenario)
    ticks, tick_s = 1200, 1.0 / 120
    anemometer = Anemometer(scenario.anemometer, wind, scenario.world.seed, 0)
    expected = np.zeros(2)
    with World(scenario) as world:
        world.set_rotor_speeds("a", [omega] * 4)
        for k in range(ticks):
            (state,) = world.states(k)
            reading = anemometer.read("a", k, k * tick_s, state.position_enu_m)
            w = np.asarray(reading.true_wind_enu_m_s[:2])
            expected = w + (expected - w) * math.exp(-rate * tick_s)
            world.step(2)
        (state,) = world.states(ticks)
    assert np.asarray(state.velocity_enu_m_s[:2]) == pytest.approx(expected, abs=0.03)
    assert abs(expected[1]) > 0.05  # the meander did move it crosswind


def test_anemometer_noise_is_seeded_per_tick_with_its_configured_std() -> None:
    scenario = parse_scenario(MEANDER)
    wind = wind_from_scenario(scenario)
    config = AnemometerSpec(period_ticks=1, noise_std_m_s=0.1)
    one = Anemometer(config, wind, 4, 0)
    errors = []
    for tick in range(4000):
        r = one.read("a", tick, tick / 120, (1.0, 2.0, 10.0))
        errors.append(np.subtract(r.wind_enu_m_s, r.true_wind_enu_m_s))
    errors_arr = np.array(errors)
    assert errors_arr.std(axis=0) == pytest.approx([0.1, 0.1, 0.1], rel=0.05)
    # the same tick gives the same reading, whenever it is asked (a physics restart)
    again = Anemometer(config, wind, 4, 0).read("a", 17, 17 / 120, (1.0, 2.0, 10.0))
    assert again == one.read("a", 17, 17 / 120, (1.0, 2.0, 10.0))
    other = Anemometer(config, wind, 4, 1).read("b", 17, 17 / 120, (1.0, 2.0, 10.0))
    assert other.wind_enu_m_s != again.wind_enu_m_s
    assert not Anemometer(AnemometerSpec(), wind, 4, 0).due(0)  # off by default


@pytest.mark.parametrize(
    "prefix", [(4, 0, 0xA7E), (100_003_001, 2, 0xA7E), (2**40 + 7, 3, 0xA7E), (0,)]
)
def test_the_noise_is_numpys_generator_seeded_by_the_tick_bit_for_bit(
    prefix: tuple[int, ...],
) -> None:
    """Each tick's draws are ``Generator(PCG64(SeedSequence([*prefix, tick]))).normal(0, σ, 3)``
    as numpy makes them, asked in any order, across seeding blocks, past 2³² (one word more)."""
    normals = SeededNormals(prefix)
    ticks = [*range(3 * SEED_BLOCK - 5, 3 * SEED_BLOCK + 5), 0, 7, SEED_BLOCK - 1, 2**32 - 1]
    ticks += [2**32, 2**40 + 3, 5]
    for tick in ticks:
        seeded = np.random.SeedSequence([*prefix, tick])
        expected = np.random.Generator(np.random.PCG64(seeded)).normal(0.0, 0.3, 3)
        assert normals.normal(tick, 0.3).tobytes() == expected.tobytes(), tick
