"""Build the concentration field a scenario describes (its plume section and its one wind)."""

from __future__ import annotations

from plume_atmosphere.wind import WindModel, wind_from_scenario
from plume_service.field import ConcentrationField, PlumeField
from plume_service.filament import FilamentPlume
from plume_service.gaussian import GaussianPlume
from plume_service.puff import PuffPlume
from swarmbus.scenario import Scenario, Source, scenario_calibration


def field_from_scenario(scenario: Scenario, wind: WindModel | None = None) -> ConcentrationField:
    """One field per source (its own model, default the plume's), superposed; all share the
    scenario's wind (``wind``: an already built one, else :func:`wind_from_scenario`)."""
    plume = scenario.plume
    wind = wind if wind is not None else wind_from_scenario(scenario)
    fields = [_source_field(scenario, index, src, wind) for index, src in enumerate(plume.sources)]
    if len(fields) == 1:
        if isinstance(fields[0], GaussianPlume):
            fields[0].preset_name = plume.preset
        return fields[0]
    return PlumeField(fields)


def _source_field(
    scenario: Scenario, index: int, src: Source, wind: WindModel
) -> ConcentrationField:
    plume = scenario.plume
    model = src.model or plume.model
    source = (src.x_m, src.y_m, src.release_height_m)
    rate, seed = src.release_rate_g_s, scenario.world.seed
    calibration = scenario_calibration(scenario)
    if model == "filament":
        return FilamentPlume(source, rate, plume.filament, wind, seed, index, calibration)
    if model == "puff":
        lid = plume.mixing_height_m
        return PuffPlume(
            source,
            rate,
            plume.puff,
            wind,
            plume.stability,
            plume.coefficients,
            lid,
            seed,
            index,
            calibration,
        )
    return GaussianPlume(
        release_rate=src.release_rate_g_s,
        wind_speed=scenario.wind.speed_m_s,
        release_height=src.release_height_m,
        stability=plume.stability,
        coefficients=plume.coefficients,
        source=(src.x_m, src.y_m),
        wind_from_deg=scenario.wind.from_deg,
        mixing_height=plume.mixing_height_m,
    )
