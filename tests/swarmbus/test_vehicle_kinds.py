"""Vehicle types by kind: the fixed wing's data as published, the multirotors unchanged."""

from __future__ import annotations

import tomllib

import msgspec
import pytest

from swarmbus.vehicle_types import VEHICLES_DIR, VehicleType, load_vehicle_type


def test_aerosonde_is_beard_and_mclain_table_e2() -> None:
    vt = load_vehicle_type("aerosonde")
    fw = vt.fixed_wing
    assert vt.kind == "fixed_wing" and fw is not None
    assert vt.actuator_count == 4 and vt.rotors == []
    # Beard & McLain (2012), table E.2
    assert vt.mass_kg == 13.5
    assert vt.inertia_kg_m2 == (0.8244, 1.135, 1.759)
    assert (fw.wing_area_m2, fw.span_m, fw.chord_m) == (0.55, 2.8956, 0.18994)
    assert (fw.c_l_0, fw.c_l_alpha, fw.c_m_alpha, fw.c_m_q) == (0.28, 3.45, -0.38, -3.6)
    assert (fw.stall_blend_m, fw.stall_alpha0_rad, fw.c_d_p) == (50.0, 0.4712, 0.0437)
    assert (fw.prop_area_m2, fw.k_motor_m_s) == (0.2027, 80.0)
    assert fw.aspect_ratio == pytest.approx(2.8956**2 / 0.55)
    p = fw.params
    assert p.fw_airspd_min < p.fw_airspd_trim < p.fw_airspd_max


@pytest.mark.parametrize("name", ["iris", "typhoon_h480"])
def test_multirotors_read_as_before(name: str) -> None:
    vt = load_vehicle_type(name)
    assert vt.kind == "multirotor" and vt.fixed_wing is None
    assert vt.actuator_count == len(vt.rotors) >= 4


def _convert(raw: dict[str, object]) -> VehicleType:
    return msgspec.convert(raw, VehicleType)


def test_a_multirotor_without_rotors_or_a_plane_without_its_table_is_refused() -> None:
    iris = tomllib.loads((VEHICLES_DIR / "iris.toml").read_text())
    with pytest.raises(msgspec.ValidationError, match="at least 3 rotors"):
        _convert({**iris, "rotors": iris["rotors"][:2]})
    with pytest.raises(msgspec.ValidationError, match="thrust_coeff_n_per_rad2_s2 > 0"):
        _convert({**iris, "thrust_coeff_n_per_rad2_s2": 0.0})
    plane = tomllib.loads((VEHICLES_DIR / "aerosonde.toml").read_text())
    with pytest.raises(msgspec.ValidationError, match=r"fixed_wing\] table"):
        _convert({k: v for k, v in plane.items() if k != "fixed_wing"})
    with pytest.raises(msgspec.ValidationError, match="no \\[\\[rotors\\]\\]"):
        _convert({**plane, "rotors": iris["rotors"]})
