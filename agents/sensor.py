"""The concentration sensor model (g/m³): what a vehicle reports from the true field value.

Stages, in order:

1. First-order response lag, starting from clean air (0) at the sensor's first sample, with a
   rise time constant while the true value is above the lag's state and a decay time constant
   while it is below (``time_constant_s`` alone: rise = decay). The plume service is asked only
   at sensor ticks (every ``period_ticks`` control ticks), so the true value between two samples
   is the one sampled at the end of the interval, held; the lag is integrated analytically over
   the interval, which is exactly what integrating it every control tick with that value gives.
   With a held value the state never crosses it, so one time constant holds for the whole
   interval. The sensor keeps its recent states: when sim time goes back (physics resumed
   from a checkpoint) it resumes from the state of its last sample before that time, so the
   replayed readings are those of a run without the restart.
2. Noise: additive Gaussian (``noise_std_g_m3``) plus proportional (``noise_rel`` × the lagged
   value), both from a generator keyed by the scenario seed, the vehicle's index and the sample's
   sim time, so a reading's noise is the same bits whoever asks and in whatever order, and a
   skipped or unavailable sample does not shift the noise of later ones.
3. Metal-oxide transducer (``[sensor.mox]``): RS/R0 = a·ppm^b capped at the clean-air ratio,
   the raw resistance RS = RS/R0 · R0, and the calibrated concentration read back through the
   same curve (a sensor at its clean-air resistance reads 0).
4. Quantisation to ``resolution_g_m3``, then the output stage: negative → 0, below the detection
   limit → 0, above saturation → saturation. The seed's 0.01 / 0.2 g/m³ window is the
   ``novak2018`` sensor preset.

With a named ``gas`` the reading also carries the reported value in ppm (ideal gas at the
scenario's ``[world]`` temperature and pressure, :mod:`swarmbus.gases`).

The field value comes from the plume service (one batched query per sensor period with the
vehicle's own and its peers' positions, see :mod:`agents.autopilot_node`); when it does not
answer, the reading is *unavailable* (values ``None``), never a silent 0.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Iterable
from typing import NamedTuple

import numpy as np

from swarmbus.gases import ppm_per_g_m3
from swarmbus.messages import ConcentrationReading, PeerReading
from swarmbus.scenario import Mox, Scenario, Sensor

Vec3 = tuple[float, float, float]


def sensor_seed(
    scenario_seed: int, vehicle_index: int, sim_time_s: float
) -> np.random.SeedSequence:
    (time_bits,) = struct.unpack("<Q", struct.pack("<d", sim_time_s))
    return np.random.SeedSequence([scenario_seed, vehicle_index, 0x5E5, time_bits])


class Measurement(NamedTuple):
    reported_g_m3: float
    resistance_ohm: float | None  # metal-oxide sensors only


class MoxCurve:
    """RS/R0 = a·ppm^b, capped at the clean-air ratio, and its inverse."""

    def __init__(self, config: Mox) -> None:
        self.config = config

    def rs_r0(self, ppm: float) -> float:
        cfg = self.config
        if ppm <= 0.0:
            return cfg.clean_air_rs_r0
        return min(cfg.rs_r0_coefficient * math.pow(ppm, cfg.rs_r0_exponent), cfg.clean_air_rs_r0)

    def ppm(self, rs_r0: float) -> float:
        """The calibrated concentration: 0 at (or above) the clean-air ratio."""
        cfg = self.config
        if rs_r0 >= cfg.clean_air_rs_r0:
            return 0.0
        return math.pow(rs_r0 / cfg.rs_r0_coefficient, 1.0 / cfg.rs_r0_exponent)


class ConcentrationSensor:
    """One vehicle's sensor; ``sample`` once per sensor period."""

    def __init__(
        self,
        config: Sensor,
        scenario_seed: int,
        vehicle_index: int,
        temperature_k: float = 298.15,
        pressure_pa: float = 101_325.0,
        history_samples: int = 1024,
    ) -> None:
        self.config = config.resolved()
        self._seed = scenario_seed
        self._index = vehicle_index
        self._rise_s = self.config.rise_s
        self._decay_s = self.config.decay_s
        gas = self.config.gas
        self._ppm_per_g_m3 = None if gas is None else ppm_per_g_m3(gas, temperature_k, pressure_pa)
        self._mox = None if self.config.mox is None else MoxCurve(self.config.mox)
        # (sim time, lag state) of the latest samples, newest last: where to resume from when
        # sim time goes back (physics resumed from a checkpoint)
        self._history: deque[tuple[float, float]] = deque(maxlen=history_samples)

    @classmethod
    def for_vehicle(cls, scenario: Scenario, vehicle_index: int) -> ConcentrationSensor:
        """The sensor of the scenario's vehicle ``vehicle_index``; it keeps its lag state for
        two physics checkpoint periods, so a resumed physics replays the same readings."""
        world, time = scenario.world, scenario.time
        period_s = time.checkpoint_period_s
        samples = math.ceil(2.0 * period_s * time.control_hz / scenario.sensor.period_ticks) + 2
        return cls(
            scenario.sensor,
            world.seed,
            vehicle_index,
            world.temperature_k,
            world.pressure_pa,
            history_samples=samples,
        )

    @property
    def lag_history(self) -> deque[tuple[float, float]]:
        """(sim time, lag state) of the latest samples, newest last (the sensor's memory)."""
        return self._history

    def resume(self, history: Iterable[tuple[float, float]]) -> None:
        """Continue from a saved :attr:`lag_history` (empty: switched on in clean air)."""
        self._history = deque(history, maxlen=self._history.maxlen)

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

    def _lag(self, true_g_m3: float, sim_time_s: float) -> float:
        history = self._history
        while history and history[-1][0] >= sim_time_s:
            history.pop()  # sim time went back: resume from the state before this sample
        if history:
            last_time_s, state = history[-1]
            dt = sim_time_s - last_time_s
        else:
            state, dt = 0.0, 0.0  # switched on in clean air
        tau = self._rise_s if true_g_m3 > state else self._decay_s
        if tau <= 0.0:
            lagged = true_g_m3
        else:
            lagged = state + (1.0 - math.exp(-dt / tau)) * (true_g_m3 - state)
        history.append((sim_time_s, lagged))
        return lagged

    def _noise(self, lagged: float, sim_time_s: float) -> float:
        cfg = self.config
        if cfg.noise_std_g_m3 <= 0.0 and cfg.noise_rel <= 0.0:
            return lagged
        rng = np.random.Generator(np.random.PCG64(sensor_seed(self._seed, self._index, sim_time_s)))
        additive, relative = rng.standard_normal(2)
        return (
            lagged + cfg.noise_std_g_m3 * float(additive) + cfg.noise_rel * lagged * float(relative)
        )

    def measure(self, true_g_m3: float, sim_time_s: float) -> Measurement:
        """The reported value (and a metal-oxide sensor's resistance) at ``sim_time_s``."""
        value = self._noise(self._lag(true_g_m3, sim_time_s), sim_time_s)
        resistance = None
        if self._mox is not None and self._ppm_per_g_m3 is not None:
            rs_r0 = self._mox.rs_r0(value * self._ppm_per_g_m3)
            resistance = rs_r0 * self._mox.config.r0_ohm
            value = self._mox.ppm(rs_r0) / self._ppm_per_g_m3
        step = self.config.resolution_g_m3
        if step > 0.0:
            value = math.floor(value / step + 0.5) * step
        return Measurement(self.output_stage(value), resistance)

    def sample(self, true_g_m3: float, sim_time_s: float) -> float:
        """The reported value for a true field value at ``sim_time_s``."""
        return self.measure(true_g_m3, sim_time_s).reported_g_m3

    def to_ppm(self, value_g_m3: float) -> float | None:
        """``value_g_m3`` in ppm of the sensor's gas; ``None`` without a gas."""
        return None if self._ppm_per_g_m3 is None else value_g_m3 * self._ppm_per_g_m3

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
                gas=self.config.gas,
            )
        reported, resistance = self.measure(true_g_m3, sim_time_s)
        return ConcentrationReading(
            vehicle_id=vehicle_id,
            sim_time_s=sim_time_s,
            position_enu_m=position,
            available=True,
            reported_g_m3=reported,
            true_g_m3=true_g_m3,
            peers=peers,
            gas=self.config.gas,
            reported_ppm=self.to_ppm(reported),
            resistance_ohm=resistance,
        )
