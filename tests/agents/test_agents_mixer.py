"""The mixer inverts an independent forward model of the rotor layout (quad and hexa)."""

from __future__ import annotations

import numpy as np
import pytest

from agents.mixer import Mixer
from swarmbus.vehicle_types import VehicleType, load_vehicle_type

TYPES = ["iris", "typhoon_h480"]


def forward(vt: VehicleType, u: list[float]) -> np.ndarray:
    """(thrust, τx, τy, τz) that rotor commands u produce, from first principles."""
    omega = np.asarray(u) * vt.max_rotor_speed_rad_s
    thrust = vt.thrust_coeff_n_per_rad2_s2 * omega**2
    total = np.zeros(4)
    for rotor, t, w in zip(vt.rotors, thrust, omega, strict=True):
        force = np.array([0.0, 0.0, t])
        total[0] += t
        total[1:] += np.cross(np.array(rotor.position_m), force)
        total[3] += -rotor.spin * vt.torque_coeff_nm_per_rad2_s2 * w**2
    return total


@pytest.mark.parametrize("name", TYPES)
@pytest.mark.parametrize(
    "request_",
    [(1.0, 0.0, 0.0, 0.0), (1.0, 0.3, 0.0, 0.0), (1.1, 0.0, -0.3, 0.0), (0.9, 0.1, 0.2, 0.05)],
)
def test_mixing_then_forward_model_reproduces_the_request(
    name: str, request_: tuple[float, ...]
) -> None:
    vt = load_vehicle_type(name)
    weight = vt.mass_kg * 9.81
    thrust = request_[0] * weight
    wanted = np.array([thrust, *request_[1:]])
    u = Mixer(vt).commands(*wanted)
    assert len(u) == len(vt.rotors)
    assert all(0.0 <= x <= 1.0 for x in u)
    np.testing.assert_allclose(forward(vt, u), wanted, atol=1e-9, rtol=1e-9)


@pytest.mark.parametrize("name", TYPES)
def test_hover_commands_are_equal_for_a_symmetric_request(name: str) -> None:
    vt = load_vehicle_type(name)
    u = Mixer(vt).commands(vt.mass_kg * 9.81, 0.0, 0.0, 0.0)
    got = forward(vt, u)
    assert got[0] == pytest.approx(vt.mass_kg * 9.81)
    assert np.abs(got[1:]).max() < 1e-9


def test_saturation_gives_up_yaw_before_roll() -> None:
    vt = load_vehicle_type("iris")
    mixer = Mixer(vt)
    weight = vt.mass_kg * 9.81
    u = mixer.commands(weight, 1.0, 0.0, 2.0)  # more yaw than the rotors can give
    got = forward(vt, u)
    assert all(0.0 <= x <= 1.0 for x in u)
    assert got[0] == pytest.approx(weight)  # thrust kept
    assert got[1] == pytest.approx(1.0)  # roll kept
    assert abs(got[2]) < 1e-9  # no pitch invented
    assert 0.0 < got[3] < 2.0  # yaw gave way


def test_commands_clip_to_the_unit_range() -> None:
    vt = load_vehicle_type("iris")
    assert Mixer(vt).commands(1e6, 0, 0, 0) == pytest.approx([1.0] * 4)
    assert Mixer(vt).commands(-5.0, 0, 0, 0) == pytest.approx([0.0] * 4)
