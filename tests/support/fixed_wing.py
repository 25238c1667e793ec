"""An Aerosonde scenario for the fixed-wing flight tests: 240/120 Hz, a 3 m/s wind from the
west (air moving toward +x), take-off altitude 30 m, one vehicle ``p`` at the origin; and the
bundled ``fixedwing`` scenario with test ports for the MAVLink tests."""

from __future__ import annotations

from pathlib import Path

from swarmbus.scenario import SCENARIOS_DIR, Scenario, parse_scenario
from swarmbus.session import free_udp_block

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


def bundled_plane_scenario(path: Path) -> tuple[Path, int, int]:
    """The bundled ``fixedwing`` scenario (swarmbus/scenarios/fixedwing.toml) with free test
    ports, in lockstep, telemetry at 4 Hz, written to ``path``; returns (path, gcs_port,
    api_port)."""
    text = (SCENARIOS_DIR / "fixedwing.toml").read_text()
    gcs, api = free_udp_block(1), free_udp_block(1)
    swaps = {
        'mode = "realtime"': 'mode = "lockstep"\nstartup_timeout_s = 60.0',
        "gcs_port = 14550": f"gcs_port = {gcs}",
        "api_port_base = 14540": f"api_port_base = {api}\ntelemetry_hz = 4.0",
    }
    for old, new in swaps.items():
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    path.write_text(text)
    return path, gcs, api
