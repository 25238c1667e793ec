"""Reading the sensor as a binary signal: which readings are detections ("in the plume").

:class:`PlumeDetector` says whether a reading is a detection: a level threshold for a fast
or lag-free sensor, the rise between two samples for a lagging one (a PID, a metal-oxide
sensor); :func:`detector_for` picks by the scenario's sensor model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behavior_state import SavesState
from agents.sensor import ConcentrationSensor
from swarmbus.messages import ConcentrationReading
from swarmbus.scenario import Sensor

#: A reading at or above this (g/m³) counts as "in the plume" (a detection) for the strategies
#: that need a binary signal. 0.001 g/m³ makes the steady novak2018 plume ≈ ±8 m wide at 50 m
#: downwind and reach beyond 100 m on its axis.
PLUME_THRESHOLD_G_M3 = 0.001


def valid_values(readings: Sequence[ConcentrationReading]) -> list[tuple[float, float, float]]:
    """(x, y, reported g/m³) of the readings that are available."""
    return [
        (r.position_enu_m[0], r.position_enu_m[1], r.reported_g_m3)
        for r in readings
        if r.available and r.reported_g_m3 is not None
    ]


#: A sensor whose decay time constant is at least this fraction of its sample period lags: it
#: gets the rise detector. After the gas leaves, a first-order output falls from a peak to a
#: level in τ·ln(peak / level); a level detector is honest while that is under one sample, i.e.
#: while ln(peak / level) < 1 / fraction. At 1/20 that holds up to peaks e^20 ≈ 5·10⁸ × the
#: level (a 65 g/m³ filament core is 6.5·10⁴ × 0.001 g/m³). The presets at the benchmark's
#: 0.1 s period: ideal and novak2018 0 (no lag) and pid-fast 0.003 keep the level; pid 13 and
#: mox-tgs2620 157 get the rise (the PID's output otherwise stays above 0.001 g/m³ for
#: ≈ 1.3 s × ln(peak / 0.001) ≈ 12 s after a strong filament).
LAG_FRACTION_OF_PERIOD = 0.05

#: A detection level is at least this many noise standard deviations
#: (:attr:`~agents.sensor.ConcentrationSensor.noise_std_g_m3`) above zero: clean air then reads
#: as a hit with a one-sided Gaussian probability of 0.13 % per sample. 3 is also how the PID
#: preset's datasheet detection limit relates to its noise (the limit taken as 3 × the std).
NOISE_MULTIPLE = 3.0


class PlumeDetector(SavesState):
    """Whether each reading is a detection ("in the plume"), one sample after another.

    ``level``: the reading is at least ``threshold_g_m3``. ``rise``: the reading rose by at
    least ``threshold_g_m3`` (and above 0) since the previous sample, a previous 0 counted as
    ``floor_g_m3`` (the sensor's detection floor: a 0 says only that the output was somewhere
    below it) — for a lagging sensor,
    which rises while gas arrives (rise time constant) and decays after it (a metal-oxide
    sensor's 15.71 s keeps one burst above 0.001 g/m³ for ≈ 2 min, a PID's 1.3 s a strong
    filament for ≈ 12 s), so a level says little about now but a rise does. Give it the
    available readings only.
    """

    state_attributes = ("previous_g_m3",)

    def __init__(
        self, mode: str = "level", threshold_g_m3: float = 0.0, floor_g_m3: float = 0.0
    ) -> None:
        if mode not in ("level", "rise"):
            raise ValueError(f"detector mode {mode!r}: valid: level, rise")
        self.mode = mode
        self.threshold_g_m3 = threshold_g_m3
        self.floor_g_m3 = floor_g_m3
        self.previous_g_m3: float | None = None

    def hit(self, value_g_m3: float) -> bool:
        previous, self.previous_g_m3 = self.previous_g_m3, value_g_m3
        if self.mode == "level":
            return value_g_m3 > 0.0 and value_g_m3 >= self.threshold_g_m3
        if previous is None:
            return False
        rise = value_g_m3 - max(previous, self.floor_g_m3)
        return rise > 0.0 and rise >= self.threshold_g_m3


def detection_level_g_m3(ctx: BehaviorContext, level_g_m3: float = PLUME_THRESHOLD_G_M3) -> float:
    """The level a detector works at for the scenario's sensor: ``level_g_m3`` raised, where it
    is lower, to the sensor's detection floor and to :data:`NOISE_MULTIPLE` × its noise std —
    a threshold below the floor would claim readings the sensor never gives, one within the
    noise would count noise as gas. The ideal sensor (no floor, no noise) keeps ``level_g_m3``."""
    sensor = _sensor(ctx)
    return max(level_g_m3, sensor.floor_g_m3, NOISE_MULTIPLE * sensor.noise_std_g_m3)


def _sensor(ctx: BehaviorContext) -> ConcentrationSensor:
    """The vehicle's sensor model (its documented floor and noise)."""
    world = ctx.scenario.world
    return ConcentrationSensor(
        ctx.scenario.sensor, world.seed, ctx.vehicle_index, world.temperature_k, world.pressure_pa
    )


def lags(sensor: Sensor, control_hz: float) -> bool:
    """Whether ``sensor``'s decay time constant is at least :data:`LAG_FRACTION_OF_PERIOD` of
    its sample period (``period_ticks`` control ticks at ``control_hz``): a lagging sensor."""
    resolved = sensor.resolved()
    period_s = resolved.period_ticks / control_hz
    return resolved.decay_s >= LAG_FRACTION_OF_PERIOD * period_s


def detector_for(ctx: BehaviorContext, level_g_m3: float = PLUME_THRESHOLD_G_M3) -> PlumeDetector:
    """The detector for the scenario's sensor.

    A sensor without a lag worth :data:`LAG_FRACTION_OF_PERIOD` of its sample period (:func:`lags`):
    a level of :func:`detection_level_g_m3` (``level_g_m3``, at least the sensor's floor and
    :data:`NOISE_MULTIPLE` × its noise std). A lagging one: a rise, per sample, of what a
    sensor in clean air shows in one sample on meeting ``level_g_m3`` — ``level_g_m3`` ×
    (1 − exp(−sample period / rise time constant)) — and at least :data:`NOISE_MULTIPLE` × √2 ×
    the noise std (the std of the difference of two samples). A rise from a 0 is measured from
    the floor: a 0 says only that the output was below it, and an output just under the floor
    (a lagging sensor's decaying tail) reads 0 and then, with noise, just over it — a jump of
    the floor's size that is not gas (measured from 0, the PID's tail made such false rises
    upwind of the source, where the searchers cast)."""
    sensor = ctx.scenario.sensor.resolved()
    if not lags(sensor, ctx.scenario.time.control_hz):
        return PlumeDetector("level", detection_level_g_m3(ctx, level_g_m3))
    model = _sensor(ctx)
    period_s = sensor.period_ticks / ctx.scenario.time.control_hz
    rise = -math.expm1(-period_s / sensor.rise_s) if sensor.rise_s > 0.0 else 1.0
    return PlumeDetector(
        "rise",
        max(level_g_m3 * rise, NOISE_MULTIPLE * math.sqrt(2.0) * model.noise_std_g_m3),
        model.floor_g_m3,
    )
