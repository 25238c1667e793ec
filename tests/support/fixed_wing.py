"""An Aerosonde scenario for the fixed-wing flight tests: 240/120 Hz, a 3 m/s wind from the
west (air moving toward +x), take-off altitude 30 m, one vehicle ``p`` at the origin."""

from __future__ import annotations

from swarmbus.scenario import Scenario, parse_scenario

WIND_ENU_M_S = (3.0, 0.0, 0.0)


def plane_scenario(failsafe: str = "", vehicle: str = "") -> Scenario:
    """``failsafe``, ``vehicle``: more TOML lines for those tables."""
    return parse_scenario(
        "[time]\nphysics_hz = 240\ncontrol_hz = 120\n"
        "[wind]\nspeed_m_s = 3.0\nfrom_deg = 270.0\n"
        f"[failsafe]\ntakeoff_altitude_m = 30.0\n{failsafe}\n"
        '[[vehicles]]\nid = "p"\ntype = "aerosonde"\nspawn_enu_m = [0.0, 0.0, 0.0]\n'
        f"{vehicle}\n"
    )
