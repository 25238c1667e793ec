"""The mixer inverts an independent forward model of the rotor layout (quad and hexa)."""

from __future__ import annotations

import math
import random
import struct

import numpy as np
import pytest

from agents.mixer import Mixer, allocation_matrix
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


def staged_commands(mixer: Mixer, thrust_n: float, tx: float, ty: float, tz: float) -> list[float]:
    """The allocation written stage by stage (every rotor's base, roll/pitch and yaw shares,
    the roll/pitch scale that fits, then the yaw scale, then the clip and the square root):
    the order of operations the mixer's bits are defined by."""
    t_max = mixer.max_rotor_thrust_n
    rows = np.linalg.pinv(allocation_matrix_of(mixer)).tolist()
    thrust_n = min(max(thrust_n, 0.0), t_max * mixer.rotor_count)
    base = [r[0] * thrust_n for r in rows]
    rp = [r[1] * tx + r[2] * ty for r in rows]
    yaw = [r[3] * tz for r in rows]

    def fit(b: list[float], d: list[float]) -> float:
        s = 1.0
        for bi, di in zip(b, d, strict=True):
            if di > 0.0 and t_max - bi < s * di:
                s = max(t_max - bi, 0.0) / di
            elif di < 0.0 and bi < -s * di:
                s = max(bi, 0.0) / -di
        return s

    s_rp = fit(base, rp)
    mid = [b + s_rp * d for b, d in zip(base, rp, strict=True)]
    s_yaw = fit(mid, yaw)
    thrusts = [min(max(m + s_yaw * d, 0.0), t_max) for m, d in zip(mid, yaw, strict=True)]
    return [min(math.sqrt(t / mixer.k_f) / mixer.omega_max, 1.0) for t in thrusts]


def allocation_matrix_of(mixer: Mixer) -> np.ndarray:
    return allocation_matrix(VEHICLES[mixer.rotor_count])


VEHICLES = {len(load_vehicle_type(n).rotors): load_vehicle_type(n) for n in TYPES}


@pytest.mark.parametrize("name", TYPES)
def test_commands_are_the_staged_allocation_bit_for_bit(name: str) -> None:
    """Saturating and not, signed zeros, NaN: the same floats as the stage-by-stage
    allocation (the published rows depend on every bit of them)."""
    vt = load_vehicle_type(name)
    mixer = Mixer(vt)
    weight = vt.mass_kg * 9.81
    rng = random.Random(7)
    specials = [0.0, -0.0, 1e-300, -1e-300, math.inf, -math.inf, math.nan]
    for k in range(20000):
        scale = rng.choice([0.001, 0.1, 1.0, 10.0])
        request = [rng.uniform(-0.5, 3.0) * weight] + [rng.gauss(0.0, scale) for _ in range(3)]
        if k % 10 == 0:
            request[rng.randrange(4)] = rng.choice(specials)
        got = mixer.commands(*request)
        want = staged_commands(mixer, *request)
        assert [struct.pack("<d", x) for x in got] == [struct.pack("<d", x) for x in want], request
