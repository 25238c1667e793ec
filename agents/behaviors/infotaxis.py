"""Infotaxis: move where the expected information about the source position is greatest.

Vergassola, M., Villermaux, E. & Shraiman, B. I. (2007), "'Infotaxis' as a strategy for
searching without gradients", Nature 445:406–409. The searcher keeps a belief b(r₀) over the
source position on a grid of ``cell_m`` cells (a box around its start: ``prior_upwind_m``
upwind, ``prior_downwind_m`` downwind, ±``prior_half_width_m`` crosswind, uniform prior).
Encounters with gas are modelled by the paper's mean rate at r from a source at r₀ (its
eq. 1, in the wind frame with x downwind):

    R(r|r₀) = R/ln(λ/a) · exp(V·(x − x₀)/2D) · K₀(|r − r₀|/λ),   λ = √(Dτ / (1 + V²τ/4D))

with V the measured wind speed and D, τ, R, a the parameters below (they shape the modelled
plume, not the simulated one). Observations are binary per decision step (the common variant
of the paper's hit counts): a *hit* when any reading of the step is at least
:data:`~agents.behaviors.detection.PLUME_THRESHOLD_G_M3` (a slow-recovery sensor: rose by the
equivalent, :func:`~agents.behaviors.detection.detector_for`), with probability
1 − exp(−(R + r_bg)·Δt)
(``background_rate_hz`` r_bg keeps a hit where the model says "no gas" from ruling a cell out
for good). After each step Bayes' rule updates b; the next step (``step_m`` upwind, downwind,
left, right, or stay) is the one with the lowest expected entropy of the updated belief,
including the chance of finding the source in the cell moved to (the paper's eq. 2).

Stopping rule: when the belief mass within ``declare_radius_m`` of its mean reaches
``declare_mass``, it declares the mean (spread: the belief's standard deviation) and holds
there. Use ``behavior = "agents.behaviors.infotaxis:Infotaxis"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.special import k0e

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3, detector_for
from agents.behaviors.seeking import SeekingBehavior, Wind
from agents.behaviors.steering import fly, toward
from agents.behaviors.wind import WindFrame
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState

FloatArray = npt.NDArray[np.float64]


def encounter_rate_hz(
    along_m: FloatArray,
    across_m: FloatArray,
    wind_speed_m_s: float,
    diffusivity_m2_s: float,
    lifetime_s: float,
    emission_rate_hz: float,
    searcher_size_m: float,
) -> FloatArray:
    """Vergassola et al.'s R(r|r₀) at offsets (along downwind, across) of r from r₀."""
    d, v, tau = diffusivity_m2_s, wind_speed_m_s, lifetime_s
    lam = math.sqrt(d * tau / (1.0 + v * v * tau / (4.0 * d)))
    dist = np.maximum(np.hypot(along_m, across_m), searcher_size_m)
    # K₀(u) = k0e(u)·e^(−u): combine the exponentials so far cells underflow to 0, never inf.
    exponent = v * along_m / (2.0 * d) - dist / lam
    with np.errstate(under="ignore"):
        rate = k0e(dist / lam) * np.exp(exponent)
    return np.asarray(emission_rate_hz / math.log(lam / searcher_size_m) * rate)


def bayes_update(belief: FloatArray, hit_probability: FloatArray, hit: bool) -> FloatArray:
    """Posterior over cells after one binary observation (normalised; the prior if all 0)."""
    likelihood = hit_probability if hit else 1.0 - hit_probability
    post = belief * likelihood
    total = post.sum()
    return belief.copy() if total <= 0.0 else np.asarray(post / total)


def entropy(belief: FloatArray) -> float:
    p = belief[belief > 0.0]
    return float(-(p * np.log(p)).sum())


class Infotaxis(SeekingBehavior):
    # ``cells_xy`` is rebuilt from ``grid_origin`` (where the grid was laid) on restore
    own_state = (
        "detector",
        "grid_origin",
        "belief",
        "target_xy",
        "step_started_s",
        "hit",
    )
    cell_m = 1.0
    step_m = 2.0
    speed_m_s = 2.0
    prior_upwind_m = 100.0
    prior_downwind_m = 20.0
    prior_half_width_m = 40.0
    diffusivity_m2_s = 1.0
    lifetime_s = 50.0
    emission_rate_hz = 100.0
    searcher_size_m = 0.1
    background_rate_hz = 0.02
    threshold_g_m3 = PLUME_THRESHOLD_G_M3
    declare_radius_m = 1.5
    declare_mass = 0.9

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.detector = detector_for(ctx, self.threshold_g_m3)
        self.cells_xy: FloatArray | None = None  # (n, 2) ENU centres
        self.grid_origin: tuple[tuple[float, float], float, float] | None = None  # wind, x, y
        self.belief: FloatArray | None = None
        self.target_xy: tuple[float, float] | None = None
        self.step_started_s = 0.0
        self.hit = False

    def restore(self, data: dict[str, Any]) -> None:
        super().restore(data)
        self.cells_xy = None
        if self.grid_origin is not None:
            belief = self.belief
            wind, x, y = self.grid_origin
            self._build_grid(WindFrame.of(wind), x, y)
            self.belief = belief

    def _build_grid(self, frame: WindFrame, x: float, y: float) -> None:
        along0, across0 = frame.coordinates(x, y)
        along = np.arange(
            along0 - self.prior_upwind_m, along0 + self.prior_downwind_m + 1e-9, self.cell_m
        )
        across = np.arange(
            across0 - self.prior_half_width_m,
            across0 + self.prior_half_width_m + 1e-9,
            self.cell_m,
        )
        a, c = np.meshgrid(along, across, indexing="ij")
        a, c = a.ravel(), c.ravel()
        dw, cw = frame.downwind, frame.crosswind
        self.cells_xy = np.column_stack([a * dw[0] + c * cw[0], a * dw[1] + c * cw[1]])
        self.belief = np.full(a.size, 1.0 / a.size)

    def hit_probability(self, frame: WindFrame, x: float, y: float, dt_s: float) -> FloatArray:
        """P(hit at (x, y) within dt | source in each cell)."""
        assert self.cells_xy is not None
        dx = x - self.cells_xy[:, 0]
        dy = y - self.cells_xy[:, 1]
        along = dx * frame.downwind[0] + dy * frame.downwind[1]
        across = dx * frame.crosswind[0] + dy * frame.crosswind[1]
        rate = encounter_rate_hz(
            along,
            across,
            frame.speed_m_s,
            self.diffusivity_m2_s,
            self.lifetime_s,
            self.emission_rate_hz,
            self.searcher_size_m,
        )
        return np.asarray(-np.expm1(-(rate + self.background_rate_hz) * dt_s))

    def _observe(self, readings: Sequence[ConcentrationReading]) -> None:
        for r in readings:
            if r.available and r.reported_g_m3 is not None and self.detector.hit(r.reported_g_m3):
                self.hit = True

    def _expected_entropy(self, frame: WindFrame, x: float, y: float, dt_s: float) -> float:
        assert self.belief is not None and self.cells_xy is not None
        b = self.belief
        p1 = self.hit_probability(frame, x, y, dt_s)
        p_hit = float((b * p1).sum())
        found = self._mass_near(x, y, 0.5 * self.cell_m)
        expected = 0.0
        for prob, hit in ((p_hit, True), (1.0 - p_hit, False)):
            if prob > 0.0:
                expected += prob * entropy(bayes_update(b, p1, hit))
        return (1.0 - found) * expected

    def _mass_near(self, x: float, y: float, radius_m: float) -> float:
        assert self.belief is not None and self.cells_xy is not None
        near = np.hypot(self.cells_xy[:, 0] - x, self.cells_xy[:, 1] - y) <= radius_m
        return float(self.belief[near].sum())

    def _decide(self, frame: WindFrame, x: float, y: float, dt_s: float) -> tuple[float, float]:
        assert self.cells_xy is not None
        lo, hi = self.cells_xy.min(axis=0), self.cells_xy.max(axis=0)
        s = self.step_m
        moves = [(0.0, 0.0), *(frame.velocity(a * s, c * s) for a, c in _DIRECTIONS)]
        best, best_xy = math.inf, (x, y)
        for mx, my in moves:
            nx, ny = x + mx, y + my
            if not (lo[0] <= nx <= hi[0] and lo[1] <= ny <= hi[1]):
                continue
            score = self._expected_entropy(frame, nx, ny, dt_s)
            if score < best - 1e-12:
                best, best_xy = score, (nx, ny)
        return best_xy

    def _belief_mean(self) -> tuple[float, float, float]:
        assert self.belief is not None and self.cells_xy is not None
        mean = self.belief @ self.cells_xy
        var = self.belief @ ((self.cells_xy - mean) ** 2)
        return float(mean[0]), float(mean[1]), float(math.sqrt(var.sum()))

    def seek(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
        wind_read: Wind,
    ) -> Setpoint | None:
        x, y, _ = own.position_enu_m
        now = own.sim_time_s
        wind, frame = wind_read.vector_m_s, wind_read.frame
        if self.belief is None:
            self.grid_origin = (wind, x, y)
            self._build_grid(frame, x, y)
            self.step_started_s = now
        self._observe(readings)
        step_dt = self.step_m / self.speed_m_s
        elapsed = now - self.step_started_s
        if self.target_xy is None:
            self.target_xy = self._decide(frame, x, y, step_dt)
        arrived = math.dist((x, y), self.target_xy) < 0.2
        if (arrived and elapsed >= 0.5 * step_dt) or elapsed > 3.0 * step_dt:
            assert self.belief is not None
            dt = max(elapsed, 0.5 * step_dt)
            self.belief = bayes_update(self.belief, self.hit_probability(frame, x, y, dt), self.hit)
            self.hit = False
            self.step_started_s = now
            mx, my, spread = self._belief_mean()
            if self._mass_near(mx, my, self.declare_radius_m) >= self.declare_mass:
                self.declaration = SourceEstimate(x_m=mx, y_m=my, sim_time_s=now, spread_m=spread)
                return None
            self.target_xy = self._decide(frame, x, y, step_dt)
        return fly(own, toward(own, *self.target_xy, self.speed_m_s), self.altitude)


# (along, across) unit moves: upwind, downwind, left, right.
_DIRECTIONS = ((-1.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
