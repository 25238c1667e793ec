"""Build the concentration field a scenario describes (its plume section and its one wind)."""

from __future__ import annotations

from plume_service.field import ConcentrationField, PlumeField
from plume_service.gaussian import GaussianPlume
from swarmbus.scenario import Scenario


def field_from_scenario(scenario: Scenario) -> ConcentrationField:
    """One Gaussian plume per source, superposed; all share the scenario's wind."""
    plume = scenario.plume
    plumes = [
        GaussianPlume(
            release_rate=src.release_rate_g_s,
            wind_speed=scenario.wind.speed_m_s,
            release_height=src.release_height_m,
            stability=plume.stability,
            coefficients=plume.coefficients,
            source=(src.x_m, src.y_m),
            wind_from_deg=scenario.wind.from_deg,
            mixing_height=plume.mixing_height_m,
        )
        for src in plume.sources
    ]
    if len(plumes) == 1:
        plumes[0].preset_name = plume.preset
        return plumes[0]
    return PlumeField(plumes)
