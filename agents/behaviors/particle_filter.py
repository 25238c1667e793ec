"""Particle-filter source-term estimation: where the source is and how much it releases.

Sequential Monte Carlo over the source term θ = (x₀, y₀, Q) with a Gaussian plume as the
forward model, as in the source-term-estimation literature (Hutchinson, Oh & Chen 2017,
"A review of source term estimation methods for atmospheric dispersion events using static or
mobile sensors", Information Fusion 36:130; Ristic, Gunatilaka & Gailis 2016, "Localisation of
a source of hazardous substance dispersion using binary measurements", Atmos. Env. 142:114).

* Prior: ``particles`` samples, (x₀, y₀) uniform on a box around the start (``prior_upwind_m``
  upwind, ``prior_downwind_m`` downwind, ±``prior_half_width_m`` crosswind), Q log-uniform on
  [``q_min_g_s``, ``q_max_g_s``].
* Forward model: :func:`swarmbus.plume_formula.gaussian_plume_g_m3` with the measured wind
  (the wind input, :mod:`agents.behaviors.search`). Assumed known, as in most STE work: the
  stability class, the σ family and the release height — taken from the scenario's
  ``[plume]`` (its first source's height).
* Likelihood of a reading y against a prediction c: ln(y + ε) − ln(c + ε) ~ N(0, σ²) with
  ε = ``floor_g_m3`` and σ = ``log_sigma`` — relative errors near the plume, insensitive to
  the tails where the sensor reads ~0.
* Resampling: systematic, when the effective sample size drops below half, followed by a
  regularisation jitter (Gaussian, ``jitter`` × the particles' spread, with a floor) so the
  cloud does not collapse onto a few values. When no particle explains a reading within 3σ,
  a fifth of the particles is redrawn from the prior (the cloud had settled on a wrong source).
* Motion: until a reading has reached :data:`~agents.behaviors.search.PLUME_THRESHOLD_G_M3`
  and the estimate's spread is below ``approach_spread_m``, crosswind sweeps of growing width
  drifting upwind (crossing the plume); then toward points ``probe_downwind_m``
  downwind of the current mean estimate, ``probe_across_m`` to alternate sides — across the
  plume close to the source, where readings are the most informative.
* Stopping rule: when the particles' horizontal spread (√(σx² + σy²)) is below
  ``declare_spread_m`` while the vehicle is probing next to the estimate (so the estimate has
  met the readings taken close to it), it declares the weighted mean (x₀, y₀, Q) with that
  spread and holds.

Use ``behavior = "agents.behaviors.particle_filter:ParticleFilter"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from agents.behavior import BehaviorContext
from agents.behaviors.search import (
    PLUME_THRESHOLD_G_M3,
    CrosswindSweep,
    SavesState,
    SourceEstimate,
    WindFrame,
    WindReader,
    anemometer_wind,
    fly,
    hold_at,
    start_or_hold,
    toward,
)
from swarmbus.dispersion import DispersionCurves, dispersion_curves
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState
from swarmbus.plume_formula import gaussian_plume_g_m3

FloatArray = npt.NDArray[np.float64]


class SourceTermFilter(SavesState):
    """The estimator alone: particles (x₀, y₀, Q) and their weights, updated reading by reading.

    Its state is the particles and weights (``rng`` is the behaviour's generator, saved with it).
    """

    state_attributes = ("particles", "weights")

    def __init__(
        self,
        particles: FloatArray,
        curves: DispersionCurves,
        release_height_m: float,
        rng: np.random.Generator,
        log_sigma: float = 0.6,
        floor_g_m3: float = 1e-4,
        jitter: float = 0.1,
        prior: Callable[[int], FloatArray] | None = None,
    ) -> None:
        self.particles = np.array(particles, dtype=np.float64)  # (n, 3): x0, y0, Q
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))
        self.curves = curves
        self.release_height_m = release_height_m
        self.rng = rng
        self.log_sigma = log_sigma
        self.floor_g_m3 = floor_g_m3
        self.jitter = jitter
        self.prior = prior

    def predict(self, x_m: float, y_m: float, z_m: float, wind: tuple[float, float]) -> FloatArray:
        """Each particle's predicted concentration at (x, y, z) in the wind (east, north)."""
        frame = WindFrame.of(wind)
        dx = x_m - self.particles[:, 0]
        dy = y_m - self.particles[:, 1]
        along = dx * frame.downwind[0] + dy * frame.downwind[1]
        across = dx * frame.crosswind[0] + dy * frame.crosswind[1]
        return gaussian_plume_g_m3(
            along,
            across,
            z_m,
            self.particles[:, 2],
            max(frame.speed_m_s, 0.1),
            self.release_height_m,
            self.curves,
        )

    def update(
        self, x_m: float, y_m: float, z_m: float, value_g_m3: float, wind: tuple[float, float]
    ) -> None:
        predicted = self.predict(x_m, y_m, z_m, wind)
        eps = self.floor_g_m3
        residual = np.log(value_g_m3 + eps) - np.log(predicted + eps)
        if self.prior is not None and np.abs(residual).min() > 3.0 * self.log_sigma:
            # No particle explains this reading: the cloud has collapsed on a wrong source.
            # Redraw a fifth of it from the prior so the filter can recover.
            fresh = self.rng.random(len(self.particles)) < 0.2
            self.particles[fresh] = self.prior(int(fresh.sum()))
            predicted[fresh] = self.predict(x_m, y_m, z_m, wind)[fresh]
            residual = np.log(value_g_m3 + eps) - np.log(predicted + eps)
        log_w = np.log(self.weights + 1e-300) - 0.5 * (residual / self.log_sigma) ** 2
        log_w -= log_w.max()
        w = np.exp(log_w)
        self.weights = w / w.sum()
        if 1.0 / float(np.sum(self.weights**2)) < 0.5 * len(self.weights):
            self._resample()

    def _resample(self) -> None:
        n = len(self.weights)
        positions = (self.rng.random() + np.arange(n)) / n
        index = np.searchsorted(np.cumsum(self.weights), positions)
        index = np.minimum(index, n - 1)
        chosen = self.particles[index]
        spread = chosen.std(axis=0)
        scale = np.maximum(self.jitter * spread, [0.05, 0.05, 0.01 * float(chosen[:, 2].mean())])
        chosen = chosen + self.rng.normal(0.0, 1.0, chosen.shape) * scale
        chosen[:, 2] = np.abs(chosen[:, 2])
        self.particles = chosen
        self.weights = np.full(n, 1.0 / n)

    def estimate(self) -> tuple[float, float, float, float]:
        """Weighted mean (x₀, y₀, Q) and the horizontal spread √(σx² + σy²)."""
        mean = self.weights @ self.particles
        var = self.weights @ (self.particles[:, :2] - mean[:2]) ** 2
        return float(mean[0]), float(mean[1]), float(mean[2]), float(math.sqrt(var.sum()))


class ParticleFilter(SavesState):
    # ``filter`` is rebuilt from ``prior_origin`` (where its prior was drawn) on restore;
    # ``rng`` is the context's generator, which the autopilot saves on its own.
    state_attributes = (
        "prior_origin",
        "altitude_m",
        "declaration",
        "detected",
        "probe_side",
        "sweep",
    )
    particles = 2000
    prior_upwind_m = 100.0
    prior_downwind_m = 20.0
    prior_half_width_m = 40.0
    q_min_g_s = 0.5
    q_max_g_s = 50.0
    speed_m_s = 2.0
    sweep_speed_m_s = 2.0
    sweep_drift_m_s = 0.5
    first_sweep_half_width_m = 5.0
    sweep_growth = 1.6
    declare_spread_m = 0.5
    probe_downwind_m = 4.0
    approach_spread_m = 5.0
    probe_across_m = 2.0
    threshold_g_m3 = PLUME_THRESHOLD_G_M3

    def __init__(self, ctx: BehaviorContext) -> None:
        self.rng = ctx.rng
        self.read_wind: WindReader = anemometer_wind(ctx)
        plume = ctx.scenario.plume
        self.curves = dispersion_curves(plume.coefficients, plume.stability)
        self.release_height_m = plume.sources[0].release_height_m
        self.filter: SourceTermFilter | None = None
        self.prior_origin: tuple[tuple[float, float], float, float] | None = None  # wind, x, y
        self.altitude_m: float | None = None
        self.declaration: SourceEstimate | None = None
        self.detected = False
        self.probe_side = 1.0
        self.sweep = CrosswindSweep(
            self.sweep_speed_m_s,
            -self.sweep_drift_m_s,
            self.first_sweep_half_width_m,
            self.sweep_growth,
            side=1.0 if ctx.vehicle_index % 2 == 0 else -1.0,
        )

    def _probe_velocity(
        self, own: VehicleState, frame: WindFrame, mx: float, my: float
    ) -> tuple[float, float]:
        """Toward a point ``probe_downwind_m`` downwind of the estimate and
        ``probe_across_m`` to one side, switching sides at each arrival: readings across the
        plume just downwind of the source separate (x₀, y₀, Q) best; at the estimate itself
        the plume reads 0 whichever nearby source is true."""
        tx, ty = frame.velocity(self.probe_downwind_m, self.probe_across_m * self.probe_side)
        tx, ty = mx + tx, my + ty
        if math.hypot(tx - own.position_enu_m[0], ty - own.position_enu_m[1]) < 0.5:
            self.probe_side = -self.probe_side
        return toward(own, tx, ty, self.speed_m_s)

    def snapshot(self) -> dict[str, Any]:
        data = super().snapshot()
        data["filter"] = None if self.filter is None else self.filter.snapshot()
        return data

    def restore(self, data: dict[str, Any]) -> None:
        super().restore(data)
        self.filter = None
        if self.prior_origin is not None:
            wind, x, y = self.prior_origin
            self.filter = self._new_filter(WindFrame.of(wind), x, y, np.empty((1, 3)))
            self.filter.restore(data["filter"])

    def _prior(self, frame: WindFrame, x: float, y: float) -> Callable[[int], FloatArray]:
        along0, across0 = frame.coordinates(x, y)
        dw, cw = frame.downwind, frame.crosswind
        rng = self.rng

        def draw(n: int) -> FloatArray:
            along = rng.uniform(along0 - self.prior_upwind_m, along0 + self.prior_downwind_m, n)
            across = rng.uniform(
                across0 - self.prior_half_width_m, across0 + self.prior_half_width_m, n
            )
            q = np.exp(rng.uniform(math.log(self.q_min_g_s), math.log(self.q_max_g_s), n))
            return np.column_stack(
                [along * dw[0] + across * cw[0], along * dw[1] + across * cw[1], q]
            )

        return draw

    def _new_filter(
        self, frame: WindFrame, x: float, y: float, particles: FloatArray | None = None
    ) -> SourceTermFilter:
        """The filter whose prior is the box around (x, y); ``particles``: drawn from it."""
        draw = self._prior(frame, x, y)
        start = draw(self.particles) if particles is None else particles
        return SourceTermFilter(start, self.curves, self.release_height_m, self.rng, prior=draw)

    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None:
        x, y, _ = own.position_enu_m
        self.altitude_m, held = start_or_hold(own, self.altitude_m, self.declaration)
        if held is not None:
            return held
        wind = self.read_wind(own)
        frame = WindFrame.of(wind)
        if self.filter is None:
            self.prior_origin = (wind, x, y)
            self.filter = self._new_filter(frame, x, y)
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            px, py, pz = r.position_enu_m
            self.filter.update(px, py, pz, r.reported_g_m3, wind)
            self.detected = self.detected or r.reported_g_m3 >= self.threshold_g_m3
        mx, my, q, spread = self.filter.estimate()
        near = math.hypot(mx - x, my - y) <= self.probe_downwind_m + self.probe_across_m + 1.0
        if self.detected and near and spread < self.declare_spread_m:
            self.declaration = SourceEstimate(
                x_m=mx, y_m=my, sim_time_s=own.sim_time_s, release_rate_g_s=q, spread_m=spread
            )
            return hold_at(mx, my, self.altitude_m)
        if self.detected and spread < self.approach_spread_m:
            return fly(own, self._probe_velocity(own, frame, mx, my), self.altitude_m)
        return fly(own, self.sweep.velocity(frame, x, y), self.altitude_m)
