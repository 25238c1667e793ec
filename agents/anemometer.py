"""A vehicle's anemometer: the scenario's wind at the vehicle's position, plus its own noise.

The wind is the one every process evaluates (:mod:`plume_atmosphere.wind`), at the tick's sim time
and the vehicle's position in that tick's state, so the anemometer reads the very air
velocity the physics applies as drag over that tick. The noise is Gaussian, ``noise_std_m_s``
on each axis, drawn from a generator seeded by (scenario seed, vehicle index, tick): the same
reading at the same tick in every run, also after a physics restart replays ticks. Readings
go out every ``period_ticks`` control ticks on ``vehicle/<id>/wind`` (0: no anemometer).
"""

from __future__ import annotations

import numpy as np

from plume_atmosphere.wind import WindModel
from swarmbus.messages import AnemometerReading
from swarmbus.scenario import AnemometerSpec

Vec3 = tuple[float, float, float]
_STREAM = 0xA7E


class Anemometer:
    """One vehicle's anemometer."""

    def __init__(
        self, config: AnemometerSpec, wind: WindModel, scenario_seed: int, vehicle_index: int
    ) -> None:
        self.config = config
        self.wind = wind
        self._seed = (scenario_seed, vehicle_index, _STREAM)

    def due(self, tick: int) -> bool:
        period = self.config.period_ticks
        return period > 0 and tick % period == 0

    def read(
        self, vehicle_id: str, tick: int, sim_time_s: float, position: Vec3
    ) -> AnemometerReading:
        uniform = self.wind.uniform_at(sim_time_s)  # the same everywhere: no lookup
        if uniform is None:
            v = self.wind.velocity([position], sim_time_s)[0]
            true = (float(v[0]), float(v[1]), float(v[2]))
        else:
            true = (float(uniform[0]), float(uniform[1]), float(uniform[2]))
        measured = true
        if self.config.noise_std_m_s > 0.0:
            rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([*self._seed, tick])))
            m = np.asarray(true) + rng.normal(0.0, self.config.noise_std_m_s, 3)
            measured = (float(m[0]), float(m[1]), float(m[2]))
        return AnemometerReading(
            vehicle_id=vehicle_id,
            sim_time_s=sim_time_s,
            position_enu_m=position,
            wind_enu_m_s=measured,
            true_wind_enu_m_s=true,
        )
