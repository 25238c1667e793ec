"""Cooperative source-term estimation: particle filters that share their readings over the radio.

Every member runs the particle filter of :mod:`agents.behaviors.particle_filter` over the
source term θ = (x₀, y₀, Q) (the single-vehicle source-term estimation of Hutchinson, Oh &
Chen 2017, its prior, Gaussian-plume forward model, zero-inflated likelihood and resampling)
and feeds it its own readings and its peers':

* **What it shares**: each 1 s window of its readings (the unit the filter updates on) as one
  :class:`Window` message: the window's start and end (sim time), its mean wind, the mean
  altitude, the mean reading, whether any reading was a detection, the weight of its
  log-likelihood (below), the reading positions (ENU centimetres, integers), and the point the
  member flies to next. A member applies the decoded message to its own filter exactly as its
  peers do, so every filter that receives the same windows multiplies its weights by the same
  tempered likelihoods. A peer's window is applied
  when it arrives, however late (a lost one is never applied).
* **Correlated windows**: in a meandering wind successive 1 s windows are not independent (the
  plume's centreline wanders with the wind's timescale T_L), and a filter that multiplies
  their likelihoods as if they were collapses its spread on a wrong source. Each window's
  log-likelihood is tempered by n_eff / n, the effective sample size per window of the series
  of the member's own windows' mean anemometer winds so far (the particle filter's
  ``likelihood = "effective"`` estimate,
  :func:`~agents.behaviors.particle_filter.effective_fraction`: the wind's meander is what
  moves the plume, and the vehicle measures it itself); for an
  Ornstein–Uhlenbeck wind of timescale T it is about ``window_s / (2 T)``. The member that
  took the window computes the weight when it closes the window and sends it in the
  :class:`Window`, so every member applies the same weight to the same window. A
  ``correlation_time_s`` T > 0 fixes the weight at ``window_s / (2 T)`` (at most 1) instead.
  Windows of different members taken at the same time share the same meander too; they are
  not tempered against each other.
* **Moves**: before any member has detected gas, the particle filter's crosswind sweeps (each
  member its own side first, by index parity). After, every window (or on reaching its point)
  a member flies to the candidate point (``step_m`` and ``2 × step_m`` away in 8 directions)
  whose detection outcome carries the most information about θ: the mutual information
  H(Σ wᵢpᵢ) − Σ wᵢH(pᵢ) of a binary detection with the particles' detection probabilities
  pᵢ (the filter's P(detection | c)): the expected entropy reduction that infotaxis
  (Vergassola, Villermaux & Shraiman 2007) maximises, for one reading. A candidate within
  ``separation_m`` of a peer's announced next point scores nothing (a plain exclusion, not
  taken from a paper), so the members do not all fly to the same point.
* **Stopping rule**: a member declares the weighted mean (x₀, y₀, Q) once the spread is below
  ``declare_spread_m`` and a window (its own or a peer's) was taken within ``near_m`` of the
  estimate (the estimate has met readings close to it).

With one vehicle, or where the runner carries no peer messages (``ctx.mailbox`` is ``None``),
a member flies alone: the same filter on its own windows only, with the tempered likelihood
and the information-driven moves. Parameters and where their values come from: docs/gsl.md.
Use ``behavior = "agents.behaviors.coop_ste:CooperativeSTE"`` on every member.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any, ClassVar

import msgspec
import numpy as np

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.particle_filter import (
    FloatArray,
    ParticleFilter,
    SourceTermFilter,
    WindowMean,
)
from agents.behaviors.seeking import SeekStep
from agents.behaviors.steering import fly, toward
from swarmbus.messages import Setpoint


class Window(msgspec.Struct, frozen=True, array_like=True):
    """A member's 1 s window of readings and its next point (ENU metres, sim seconds)."""

    start_s: float
    end_s: float
    wind_e_m_s: float
    wind_n_m_s: float
    z_m: float
    mean_g_m3: float
    detected: bool
    tempering: float  # the weight of its log-likelihood in every member's filter
    x_cm: list[int]
    y_cm: list[int]
    next_x_m: float
    next_y_m: float

    def points(self) -> list[tuple[float, float, float]]:
        return [(x / 100.0, y / 100.0, self.z_m) for x, y in zip(self.x_cm, self.y_cm, strict=True)]


def window_message(
    start_s: float,
    end_s: float,
    window: WindowMean,
    next_point: tuple[float, float],
    max_points: int,
    tempering: float,
) -> Window:
    """The :class:`Window` of a window's readings: at most ``max_points`` positions (evenly
    thinned), to the centimetre, at their mean altitude; its log-likelihood weighted by
    ``tempering``."""
    points, value_g_m3, wind, detected = window
    if len(points) > max_points:
        keep = np.linspace(0, len(points) - 1, max_points).round().astype(int)
        points = [points[int(i)] for i in keep]
    return Window(
        start_s=start_s,
        end_s=end_s,
        wind_e_m_s=wind[0],
        wind_n_m_s=wind[1],
        z_m=sum(p[2] for p in points) / len(points),
        mean_g_m3=value_g_m3,
        detected=detected,
        tempering=tempering,
        x_cm=[round(p[0] * 100.0) for p in points],
        y_cm=[round(p[1] * 100.0) for p in points],
        next_x_m=next_point[0],
        next_y_m=next_point[1],
    )


def apply_window(source_filter: SourceTermFilter, window: Window) -> None:
    """One shared window into a member's filter (the same call on every member): its
    log-likelihood weighted by the window's own ``tempering``."""
    wind = (window.wind_e_m_s, window.wind_n_m_s)
    source_filter.tempering = window.tempering
    source_filter.update_mean(window.points(), window.mean_g_m3, wind, window.detected)


def binary_information(source_filter: SourceTermFilter, p_det: FloatArray) -> FloatArray:
    """Mutual information (nats) between θ and a detection at each candidate: ``p_det`` is
    (candidates, particles), P(detection | particle) at each candidate."""

    def entropy(p: FloatArray) -> FloatArray:
        q = np.clip(p, 1e-12, 1.0 - 1e-12)
        return np.asarray(-(q * np.log(q) + (1.0 - q) * np.log1p(-q)))

    w = source_filter.weights
    return np.asarray(entropy(p_det @ w) - entropy(p_det) @ w)


class CooperativeSTE(ParticleFilter):
    vehicles = 3
    source = (
        "source-term estimation (Hutchinson, Oh & Chen 2017) with readings shared over the "
        "radio and information-driven moves"
    )
    talks: ClassVar[bool] = True
    own_state: ClassVar[tuple[str, ...]] = (
        *ParticleFilter.own_state,
        "window_points",
        "peer_points",
        "target",
        "swarm_detected",
    )
    # σy of the class-D plume (McMullen) 50 m downwind, the middle of the starts' 30–80 m:
    # members one plume half-width apart sweep across it side by side
    start_spacing_m = 4.0
    correlation_time_s = 0.0  # 0: estimated online from the own anemometer's windows
    step_m = 3.0
    separation_m = 2.0
    near_m = 7.0
    max_points = 12

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        correlation = self.correlation_time_s
        # None: each window's weight is estimated from the own windows' winds (_update)
        self.fixed_tempering = (
            min(1.0, self.window_s / (2.0 * correlation)) if correlation > 0.0 else None
        )
        self.window_points: deque[tuple[float, float]] = deque(maxlen=100)  # windows' centres
        self.peer_points: dict[str, tuple[float, float]] = {}  # each peer's announced point
        self.target: tuple[float, float] | None = None
        self.swarm_detected = False
        angles = np.arange(8) * (math.pi / 4.0)
        ring = np.column_stack([np.cos(angles), np.sin(angles)])
        self.offsets = np.vstack([ring * self.step_m, ring * 2.0 * self.step_m])

    def _apply(self, window: Window) -> None:
        assert self.filter is not None
        apply_window(self.filter, window)
        self.swarm_detected = self.swarm_detected or window.detected
        points = window.points()
        cx = sum(p[0] for p in points) / len(points)
        cy = sum(p[1] for p in points) / len(points)
        self.window_points.append((cx, cy))

    def _update(self, now_s: float, window: WindowMean) -> None:
        assert self.window_start_s is not None
        here = window.points[-1][:2]
        tempering = self.fixed_tempering
        if tempering is None:
            tempering = self._online_tempering(window.wind)
        message = window_message(
            self.window_start_s, now_s, window, self.target or here, self.max_points, tempering
        )
        self._apply(message)
        if self.mailbox is not None:
            self.mailbox.publish(message)
        self.target = None  # a new window: choose the next point

    def _choose(
        self, x: float, y: float, z: float, wind: tuple[float, float]
    ) -> tuple[float, float]:
        """The candidate point whose detection tells the most about θ, away from the peers'
        announced points."""
        assert self.filter is not None
        candidates = self.offsets + np.array([x, y])
        predicted = self.filter.predict(candidates[:, :1], candidates[:, 1:2], z, wind)
        score = binary_information(self.filter, self.filter.detection_probability(predicted))
        for px, py in self.peer_points.values():
            taken = np.hypot(candidates[:, 0] - px, candidates[:, 1] - py) < self.separation_m
            score[taken] = -1.0
        best = candidates[int(np.argmax(score))]
        return float(best[0]), float(best[1])

    def seek(self, step: SeekStep) -> Setpoint | None:
        own = step.own
        x, y, z = own.position_enu_m
        wind, frame = step.wind.vector_m_s, step.wind.frame
        if self.filter is None:
            self.prior_origin = (wind, x, y)
            self.filter = self._new_filter(frame, x, y)
        for received in sorted(step.inbox, key=lambda r: (r.sent_tick, r.sender)):
            if isinstance(received.message, Window):
                self._apply(received.message)
                m = received.message
                self.peer_points[received.sender] = (m.next_x_m, m.next_y_m)
        self._average(own.sim_time_s, step.readings, wind)
        self.swarm_detected = self.swarm_detected or self.detected
        mx, my, q, spread = self.filter.estimate()
        near = any(math.hypot(mx - px, my - py) <= self.near_m for px, py in self.window_points)
        if self.swarm_detected and near and spread < self.declare_spread_m:
            self.declaration = SourceEstimate(
                x_m=mx, y_m=my, sim_time_s=own.sim_time_s, release_rate_g_s=q, spread_m=spread
            )
            return None
        if not self.swarm_detected:
            return fly(own, self.sweep.velocity(frame, x, y), self.altitude)
        if self.target is None or math.hypot(self.target[0] - x, self.target[1] - y) < 0.5:
            self.target = self._choose(x, y, z, wind)
        return fly(own, toward(own, *self.target, self.speed_m_s), self.altitude)

    def restore(self, data: dict[str, Any]) -> None:
        super().restore(data)
        self.window_points = deque(self.window_points, maxlen=100)
