"""Surge-cast: surge straight upwind while in the plume, cast crosswind only after losing it.

Lochmatter, T. & Martinoli, A. (2008), "Tracking odor plumes in a laminar wind field with
bio-inspired algorithms", *Experimental Robotics* (ISER 2008), Springer STAR 54:473–482; and
Lochmatter's thesis (EPFL 2010); made for an intermittent plume as the moth does it (Kennedy &
Marsh 1974): keep surging through blanks shorter than the plume's typical blank, cast without
drifting downwind, and declare the source on evidence, never at the first strong whiff. The
sensor is read as binary: a detection when the reading is at least
:data:`~agents.behaviors.detection.PLUME_THRESHOLD_G_M3` (with a lagging sensor such as the
PID and metal-oxide presets: when it rose by the equivalent per sample,
:func:`~agents.behaviors.detection.detector_for`).

States (``self.tracker.state``, :class:`~agents.behaviors.tracking.PlumeTracker`):

* ``"search"`` — nothing detected yet: crosswind legs of growing width around the start;
* ``"surge"`` — a detection within the hit memory (2 s): fly straight upwind at
  ``surge_speed_m_s`` in the frame of the wind averaged over the last 3 s;
* ``"back"`` — the plume was lost: straight downwind to the cast line, 1.5 m upwind of the
  most upwind detection (the frontier);
* ``"cast"`` — crosswind legs of growing width (first ``first_cast_half_width_m``,
  ×``cast_growth`` per leg, at most ``max_cast_half_width_m``) along the line, no drift.

It declares the source between the frontier and the line once a cast of eight legs there has
found nothing (:mod:`agents.behaviors.tracking` has the rule and where each number comes
from) and holds over it. Use ``behavior = "agents.behaviors.surge_cast:SurgeCast"``; it holds
the altitude it starts at.
"""

from __future__ import annotations

from agents.behaviors.tracking import TrackingBehavior


class SurgeCast(TrackingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    surge_speed_m_s = 2.0
    cast_speed_m_s = 2.5
    first_cast_half_width_m = 3.0
    cast_growth = 1.6
    max_cast_half_width_m = 20.0

    @property
    def state(self) -> str:
        return self.tracker.state

    def surge_across_m_s(self) -> float:
        return 0.0  # straight upwind
