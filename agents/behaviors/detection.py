"""Reading the sensor as a binary signal: which readings are detections ("in the plume").

:class:`PlumeDetector` says whether a reading is a detection: a level threshold for a fast
sensor, the rise between two samples for a slow-recovery (metal-oxide) sensor;
:func:`detector_for` picks by the scenario's sensor model.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from agents.behavior import BehaviorContext
from agents.behavior_state import SavesState
from swarmbus.messages import ConcentrationReading

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


#: A sensor whose decay time constant is longer than this (s) recovers too slowly for a level
#: threshold: after one burst its reading stays above the threshold for minutes.
SLOW_DECAY_S = 5.0


class PlumeDetector(SavesState):
    """Whether each reading is a detection ("in the plume"), one sample after another.

    ``level``: the reading is at least ``threshold_g_m3``. ``rise``: the reading rose by at
    least ``threshold_g_m3`` (and above 0) since the previous sample — for a slow-recovery
    sensor, which rises while gas arrives (rise time constant) and decays slowly after it
    (a metal-oxide sensor's 15.71 s keeps one burst above 0.001 g/m³ for ≈ 2 min), so a
    level says little about now but a rise does. Give it the available readings only.
    """

    state_attributes = ("previous_g_m3",)

    def __init__(self, mode: str = "level", threshold_g_m3: float = 0.0) -> None:
        if mode not in ("level", "rise"):
            raise ValueError(f"detector mode {mode!r}: valid: level, rise")
        self.mode = mode
        self.threshold_g_m3 = threshold_g_m3
        self.previous_g_m3: float | None = None

    def hit(self, value_g_m3: float) -> bool:
        previous, self.previous_g_m3 = self.previous_g_m3, value_g_m3
        if self.mode == "level":
            return value_g_m3 > 0.0 and value_g_m3 >= self.threshold_g_m3
        if previous is None:
            return False
        rise = value_g_m3 - previous
        return rise > 0.0 and rise >= self.threshold_g_m3


def detector_for(ctx: BehaviorContext, level_g_m3: float = PLUME_THRESHOLD_G_M3) -> PlumeDetector:
    """The detector for the scenario's sensor: a level of ``level_g_m3`` for a fast sensor;
    for a slow-recovery one (decay time constant > :data:`SLOW_DECAY_S`) a rise, per sample,
    of what a sensor in clean air shows in one sample on meeting ``level_g_m3``:
    ``level_g_m3`` × (1 − exp(−sample period / rise time constant))."""
    sensor = ctx.scenario.sensor.resolved()
    if sensor.decay_s <= SLOW_DECAY_S:
        return PlumeDetector("level", level_g_m3)
    period_s = sensor.period_ticks / ctx.scenario.time.control_hz
    rise = -math.expm1(-period_s / sensor.rise_s) if sensor.rise_s > 0.0 else 1.0
    return PlumeDetector("rise", level_g_m3 * rise)
