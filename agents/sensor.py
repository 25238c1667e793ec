"""The concentration sensor model (g/m³): what a vehicle reports from the true field value.

A linear sensor (no ``[sensor.mox]``, or no ``gas``), in order:

1. First-order response, starting from clean air (0) at the sensor's first sample, with a rise
   time constant while the true value is above the filter's state and a decay time constant
   while it is below (``time_constant_s`` alone: rise = decay).
2. Noise: additive Gaussian (``noise_std_g_m3``) plus proportional (``noise_rel`` × the filtered
   value).

A metal-oxide sensor (``[sensor.mox]`` with a ``gas``), as GADEN models it, in order:

1. Transducer: the true value in ppm → RS/R0 = a·ppm^b, capped at the clean-air ratio.
2. First-order response on RS/R0, starting at the clean-air ratio: the rise time constant
   while RS/R0 falls (gas arriving), the decay one while it rises (gas leaving). The filter
   acts on the resistance, not on the concentration, so a short strong hit moves RS/R0 only a
   little and the sensor reads little (0.1 s at 65 g/m³ of ethanol peaks at ≈ 0.009 g/m³).
3. The measured resistance RS = RS/R0 · R0 · (1 + drift rate · t) · (1 + ``rs_noise_rel``·N):
   each sensor's baseline drifts linearly in sim time at a rate drawn once per vehicle
   (std ``r0_drift_rel_per_h`` per hour), and every sample has relative resistance noise.
4. Calibration: RS / nominal R0 read back through the inverse curve; at or above the clean-air
   ratio the calibrated value is 0. The clean-air ratio is the sensor's detection floor
   (:attr:`ConcentrationSensor.floor_g_m3`, 4.57 ppm ≈ 0.0086 g/m³ of ethanol for the
   TGS2620): the smallest non-zero calibrated value. ``noise_std_g_m3``/``noise_rel``, if set,
   are added to the calibrated value.

Both then quantise to ``resolution_g_m3`` and apply the output stage: a value below the floor
(the detection limit, and for a metal-oxide sensor its clean-air value) or negative → 0, above
saturation → saturation. So a reading is either 0 or at least the floor.

Sampling: the plume service is asked only at sensor ticks (every ``period_ticks`` control
ticks), so the true value between two samples is the one sampled at the end of the interval,
held; the filter is integrated analytically over the interval, which is exactly what
integrating it every control tick with that value gives. The sensor keeps its recent filter
states: when sim time goes back (physics resumed from a checkpoint) it resumes from the state
of its last sample before that time, so the replayed readings are those of a run without the
restart. Noise comes from a generator keyed by the scenario seed, the vehicle's index and the
sample's sim time, the drift rate from one keyed by the seed and the index, so a reading is
the same bits whoever asks and in whatever order, and a skipped or unavailable sample does not
shift later ones.

:attr:`ConcentrationSensor.floor_g_m3` and :attr:`ConcentrationSensor.noise_std_g_m3` are what
a detection threshold must clear. The seed's 0.01 / 0.2 g/m³ window is the ``novak2018``
preset. With a named ``gas`` the reading also carries the reported value in ppm (ideal gas at
the scenario's ``[world]`` temperature and pressure, :mod:`plume_atmosphere.gases`).

The field value comes from the plume service (one batched query per sensor period with the
vehicle's own and its peers' positions, see :mod:`agents.autopilot_node`); when it does not
answer, the reading is *unavailable* (values ``None``), never a silent 0.
"""

from __future__ import annotations

import math
import struct
from collections import deque
from collections.abc import Callable, Iterable
from typing import NamedTuple

import numpy as np

from plume_atmosphere.gases import ppm_per_g_m3
from swarmbus.messages import ConcentrationReading, PeerReading
from swarmbus.scenario import Mox, Scenario, Sensor

Vec3 = tuple[float, float, float]


def sensor_seed(
    scenario_seed: int, vehicle_index: int, sim_time_s: float
) -> np.random.SeedSequence:
    (time_bits,) = struct.unpack("<Q", struct.pack("<d", sim_time_s))
    return np.random.SeedSequence([scenario_seed, vehicle_index, 0x5E5, time_bits])


def drift_seed(scenario_seed: int, vehicle_index: int) -> np.random.SeedSequence:
    """The generator of a vehicle's baseline drift rate (one draw, fixed for the run)."""
    return np.random.SeedSequence([scenario_seed, vehicle_index, 0xD21F7])


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

    @property
    def floor_ppm(self) -> float:
        """Where the curve meets the clean-air ratio: the smallest non-zero calibrated value."""
        cfg = self.config
        return math.pow(cfg.clean_air_rs_r0 / cfg.rs_r0_coefficient, 1.0 / cfg.rs_r0_exponent)


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
        self._mox = None
        self._drift_per_s = 0.0
        mox = self.config.mox
        if mox is not None and gas is not None:
            self._mox = MoxCurve(mox)
            if mox.r0_drift_rel_per_h > 0.0:
                rng = np.random.Generator(np.random.PCG64(drift_seed(scenario_seed, vehicle_index)))
                self._drift_per_s = mox.r0_drift_rel_per_h * float(rng.standard_normal()) / 3600.0
        # (sim time, filter state) of the latest samples, newest last: where to resume from
        # when sim time goes back (physics resumed from a checkpoint). The state is the
        # concentration (g/m³) of a linear sensor, RS/R0 of a metal-oxide one.
        self._history: deque[tuple[float, float]] = deque(maxlen=history_samples)

    @classmethod
    def for_vehicle(cls, scenario: Scenario, vehicle_index: int) -> ConcentrationSensor:
        """The sensor of the scenario's vehicle ``vehicle_index``; it keeps its filter state for
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
        """(sim time, filter state) of the latest samples, newest last (the sensor's memory)."""
        return self._history

    def resume(self, history: Iterable[tuple[float, float]]) -> None:
        """Continue from a saved :attr:`lag_history` (empty: switched on in clean air)."""
        self._history = deque(history, maxlen=self._history.maxlen)

    def due(self, tick: int) -> bool:
        return tick % self.config.period_ticks == 0

    # ------------------------------------------------------------------ documented limits
    @property
    def floor_g_m3(self) -> float:
        """The detection floor: the smallest non-zero reading (below it the output is 0). The
        detection limit, and for a metal-oxide sensor at least its clean-air value (the curve
        at the clean-air ratio)."""
        floor = self.config.detection_limit_g_m3
        if self._mox is not None and self._ppm_per_g_m3 is not None:
            floor = max(floor, self._mox.floor_ppm / self._ppm_per_g_m3)
        return floor

    @property
    def noise_std_g_m3(self) -> float:
        """The std of a reading just above the floor (g/m³): set a detection threshold some
        multiples of it above :attr:`floor_g_m3`. A metal-oxide sensor's relative resistance
        noise σ becomes |1/b|·σ relative noise of the calibrated value (b: the curve's
        exponent); the baseline drift is a slow bias, not counted here."""
        cfg = self.config
        floor = self.floor_g_m3
        direct = cfg.noise_std_g_m3 + cfg.noise_rel * floor
        if self._mox is None:
            return direct
        mox = self._mox.config
        resistance = mox.rs_noise_rel / abs(mox.rs_r0_exponent) * floor
        return math.hypot(direct, resistance)

    def output_stage(self, value_g_m3: float) -> float:
        """Detection floor and saturation: below the floor (or ≤ 0) → 0."""
        cfg = self.config
        if value_g_m3 < self.floor_g_m3 or value_g_m3 <= 0.0:
            return 0.0
        if cfg.saturation_g_m3 is not None and value_g_m3 > cfg.saturation_g_m3:
            return cfg.saturation_g_m3
        return value_g_m3

    # ------------------------------------------------------------------ the model
    def _filter(
        self, target: float, sim_time_s: float, clean: float, rising: Callable[[float], bool]
    ) -> float:
        """The first-order response toward ``target`` over the interval since the last sample;
        ``rising``: the rise time constant applies (gas arriving), else the decay one."""
        history = self._history
        while history and history[-1][0] >= sim_time_s:
            history.pop()  # sim time went back: resume from the state before this sample
        if history:
            last_time_s, state = history[-1]
            dt = sim_time_s - last_time_s
        else:
            state, dt = clean, 0.0  # switched on in clean air
        tau = self._rise_s if rising(state) else self._decay_s
        # No lag: the value itself, since state + 1·(target − state) may round off by an ulp.
        filtered = target if tau <= 0.0 else state + (1.0 - math.exp(-dt / tau)) * (target - state)
        history.append((sim_time_s, filtered))
        return filtered

    def _normals(self, sim_time_s: float) -> tuple[float, float, float]:
        """Additive, relative and resistance noise draws of the sample at ``sim_time_s``."""
        rng = np.random.Generator(np.random.PCG64(sensor_seed(self._seed, self._index, sim_time_s)))
        additive, relative, resistance = rng.standard_normal(3)
        return float(additive), float(relative), float(resistance)

    def _noisy(self, value: float, draws: tuple[float, float, float] | None) -> float:
        cfg = self.config
        if draws is None or (cfg.noise_std_g_m3 <= 0.0 and cfg.noise_rel <= 0.0):
            return value
        return value + cfg.noise_std_g_m3 * draws[0] + cfg.noise_rel * value * draws[1]

    def _draws(self, sim_time_s: float) -> tuple[float, float, float] | None:
        cfg = self.config
        resistance_noise = cfg.mox is not None and cfg.mox.rs_noise_rel > 0.0
        if cfg.noise_std_g_m3 <= 0.0 and cfg.noise_rel <= 0.0 and not resistance_noise:
            return None
        return self._normals(sim_time_s)

    def _mox_measure(
        self, mox: MoxCurve, ppm_per_g_m3: float, true_g_m3: float, sim_time_s: float
    ) -> tuple[float, float]:
        """(calibrated g/m³, measured resistance Ω) of a metal-oxide sensor."""
        cfg = mox.config
        target = mox.rs_r0(true_g_m3 * ppm_per_g_m3)
        rs_r0 = self._filter(target, sim_time_s, cfg.clean_air_rs_r0, lambda s: target < s)
        draws = self._draws(sim_time_s)
        resistance = rs_r0 * cfg.r0_ohm * (1.0 + self._drift_per_s * sim_time_s)
        if draws is not None and cfg.rs_noise_rel > 0.0:
            resistance *= 1.0 + cfg.rs_noise_rel * draws[2]
        value = mox.ppm(resistance / cfg.r0_ohm) / ppm_per_g_m3
        return self._noisy(value, draws), resistance

    def measure(self, true_g_m3: float, sim_time_s: float) -> Measurement:
        """The reported value (and a metal-oxide sensor's resistance) at ``sim_time_s``."""
        resistance = None
        if self._mox is not None and self._ppm_per_g_m3 is not None:
            value, resistance = self._mox_measure(
                self._mox, self._ppm_per_g_m3, true_g_m3, sim_time_s
            )
        else:
            filtered = self._filter(true_g_m3, sim_time_s, 0.0, lambda s: true_g_m3 > s)
            value = self._noisy(filtered, self._draws(sim_time_s))
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
        """A bus reading; ``true_g_m3`` ``None`` (plume service silent) → unavailable (no
        value, no peers)."""
        reported: float | None = None
        resistance: float | None = None
        if true_g_m3 is not None:
            reported, resistance = self.measure(true_g_m3, sim_time_s)
        return ConcentrationReading(
            vehicle_id=vehicle_id,
            sim_time_s=sim_time_s,
            position_enu_m=position,
            available=true_g_m3 is not None,
            reported_g_m3=reported,
            true_g_m3=true_g_m3,
            peers=peers if true_g_m3 is not None else [],
            gas=self.config.gas,
            reported_ppm=None if reported is None else self.to_ppm(reported),
            resistance_ohm=resistance,
        )
