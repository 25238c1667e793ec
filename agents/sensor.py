"""The concentration sensor model (g/m³): what a vehicle reports from the true field value.

Stages, in order: first-order response lag (``time_constant_s``, exact discretisation over the
time since the last sample), additive Gaussian noise (``noise_std_g_m3``, a numpy Generator
seeded from the scenario seed and the vehicle's index, so runs repeat), then the output stage:
negative → 0, below the detection limit → 0, above saturation → saturation. The seed's
0.01 / 0.2 g/m³ window is the ``novak2018`` sensor preset.

The field value comes from the plume service (one batched query per sensor period with the
vehicle's own and its peers' positions, see :mod:`agents.autopilot_node`); when it does not
answer, the reading is *unavailable* (values ``None``), never a silent 0.
"""

from __future__ import annotations

import math

import numpy as np

from swarmbus.messages import ConcentrationReading, PeerReading
from swarmbus.scenario import Sensor

Vec3 = tuple[float, float, float]


def sensor_seed(scenario_seed: int, vehicle_index: int) -> np.random.SeedSequence:
    return np.random.SeedSequence([scenario_seed, vehicle_index, 0x5E5])


class ConcentrationSensor:
    """One vehicle's sensor; ``sample`` once per sensor period."""

    def __init__(self, config: Sensor, scenario_seed: int, vehicle_index: int) -> None:
        self.config = config.resolved()
        self._rng = np.random.Generator(np.random.PCG64(sensor_seed(scenario_seed, vehicle_index)))
        self._lagged: float | None = None
        self._last_time_s: float | None = None

    def due(self, tick: int) -> bool:
        return tick % self.config.period_ticks == 0

    def output_stage(self, value_g_m3: float) -> float:
        """Detection limit and saturation (what the seed's thresholds did)."""
        cfg = self.config
        if value_g_m3 < cfg.detection_limit_g_m3 or value_g_m3 <= 0.0:
            return 0.0
        if cfg.saturation_g_m3 is not None and value_g_m3 > cfg.saturation_g_m3:
            return cfg.saturation_g_m3
        return value_g_m3

    def sample(self, true_g_m3: float, sim_time_s: float) -> float:
        """The reported value for a true field value at ``sim_time_s``."""
        cfg = self.config
        tau = cfg.time_constant_s
        if self._lagged is None or self._last_time_s is None or tau <= 0.0:
            lagged = true_g_m3
        else:
            dt = max(sim_time_s - self._last_time_s, 0.0)
            lagged = self._lagged + (1.0 - math.exp(-dt / tau)) * (true_g_m3 - self._lagged)
        self._lagged = lagged
        self._last_time_s = sim_time_s
        value = lagged
        if cfg.noise_std_g_m3 > 0.0:
            value += float(self._rng.normal(0.0, cfg.noise_std_g_m3))
        return self.output_stage(value)

    def reading(
        self,
        vehicle_id: str,
        sim_time_s: float,
        position: Vec3,
        true_g_m3: float | None,
        peers: list[PeerReading],
    ) -> ConcentrationReading:
        """A bus reading; ``true_g_m3`` ``None`` (plume service silent) → unavailable."""
        if true_g_m3 is None:
            return ConcentrationReading(
                vehicle_id=vehicle_id,
                sim_time_s=sim_time_s,
                position_enu_m=position,
                available=False,
                reported_g_m3=None,
                true_g_m3=None,
            )
        return ConcentrationReading(
            vehicle_id=vehicle_id,
            sim_time_s=sim_time_s,
            position_enu_m=position,
            available=True,
            reported_g_m3=self.sample(true_g_m3, sim_time_s),
            true_g_m3=true_g_m3,
            peers=peers,
        )
