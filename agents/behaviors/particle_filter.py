"""Particle-filter source-term estimation: where the source is and how much it releases.

Sequential Monte Carlo over the source term θ = (x₀, y₀, Q) with a Gaussian plume as the
forward model, as in the source-term-estimation literature (Hutchinson, Oh & Chen 2017,
"A review of source term estimation methods for atmospheric dispersion events using static or
mobile sensors", Information Fusion 36:130; Ristic, Gunatilaka & Gailis 2016, "Localisation of
a source of hazardous substance dispersion using binary measurements", Atmos. Env. 142:114).

* Prior: ``particles`` samples, (x₀, y₀) uniform on a box around the start (``prior_upwind_m``
  upwind, ``prior_downwind_m`` downwind, ±``prior_half_width_m`` crosswind), Q log-uniform on
  [``q_min_g_s``, ``q_max_g_s``].
* Forward model: :func:`plume_atmosphere.plume_formula.gaussian_plume_g_m3` with the measured wind
  (the wind input, :mod:`agents.behaviors.wind`). Assumed known, as in most STE work: the
  stability class, the σ family and the release height — taken from the scenario's
  ``[plume]`` (its first source's height).
* Readings: averaged over ``window_s`` (1 s); the filter updates once per window with the
  window's mean reading against each particle's prediction averaged over the window's
  reading positions, in the window's mean wind.
* Likelihood: zero-inflated (Hutchinson et al.'s UAV source-term estimation,
  :meth:`SourceTermFilter.log_likelihood`): a background (false-hit) probability, a miss
  probability where the model predicts gas, the detection probability from the model mean,
  and a log-normal magnitude term for a detection (``window_log_sigma``, floored at 3σ).
* Resampling: systematic, when the effective sample size drops below half, followed by a
  regularisation jitter (Gaussian, ``jitter`` × the particles' spread, with a floor) so the
  cloud does not collapse onto a few values. When no particle explains a reading within 3σ,
  a fifth of the particles is redrawn from the prior (the cloud had settled on a wrong source).
* Motion: until a reading has reached :data:`~agents.behaviors.detection.PLUME_THRESHOLD_G_M3`
  and the estimate's spread is below ``approach_spread_m``, crosswind sweeps of growing width
  drifting upwind (crossing the plume); then toward points ``probe_downwind_m``
  downwind of the current mean estimate, ``probe_across_m`` to alternate sides — across the
  plume close to the source, where readings are the most informative.
* Stopping rule: when the particles' horizontal spread (√(σx² + σy²)) is below
  ``declare_spread_m`` (1 m) while the vehicle is probing next to the estimate (so the estimate has
  met the readings taken close to it), it declares the weighted mean (x₀, y₀, Q) with that
  spread and holds.
* Correlated windows (``likelihood``): ``"independent"`` (the default) multiplies the windows'
  likelihoods as if each were independent evidence. In a meandering wind successive windows
  share the plume's wander and are not: ``"effective"`` multiplies each window's
  log-likelihood by n_eff / n, the effective sample size per window of the series of the
  windows' mean anemometer winds so far (:func:`effective_fraction`: the wind's meander is what
  moves the plume, and the vehicle measures it itself), so a run of n correlated windows counts
  as n_eff independent ones. With it the stopping rule is the posterior's: the particles'
  weight within ``declare_radius_m`` (2 m) of the estimate is at least ``declare_mass`` (0.9),
  i.e. the filter is 90 % sure the source is within 2 m; it starts probing once its spread is
  below ``effective_approach_spread_m`` (20 m).

Use ``behavior = "agents.behaviors.particle_filter:ParticleFilter"``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar, NamedTuple

import numpy as np
import numpy.typing as npt

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behavior_state import SavesState
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import CrosswindSweep, fly, toward
from agents.behaviors.wind import WindFrame
from plume_atmosphere.dispersion import DispersionCurves, dispersion_curves
from plume_atmosphere.plume_formula import gaussian_plume_g_m3
from swarmbus.errors import FieldError
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState

FloatArray = npt.NDArray[np.float64]


LIKELIHOODS = ("independent", "effective")


def autocorrelation(series: npt.ArrayLike) -> FloatArray:
    """The sample autocorrelation ρ(0 … n − 1) of ``series`` ((n,) or (n, d): the d
    components' mean-removed lagged products pooled), biased (divided by n, as
    Geyer 1992 takes it)."""
    x = np.asarray(series, dtype=np.float64)
    x = x.reshape(len(x), -1) - x.reshape(len(x), -1).mean(axis=0)
    n = len(x)
    products = np.zeros(n)
    for c in x.T:
        products += np.correlate(c, c, mode="full")[n - 1 :]
    if products[0] <= 0.0:
        return np.zeros(n)
    return np.asarray(products / products[0], dtype=np.float64)


def effective_fraction(series: npt.ArrayLike) -> float:
    """n_eff / n of a stationary series: 1 / τ, τ = 1 + 2 Σ ρ(k) the integrated
    autocorrelation time in samples, summed by Geyer's initial monotone sequence (Geyer 1992,
    "Practical Markov chain Monte Carlo", Stat. Sci. 7:473): the pair sums
    Γₘ = ρ(2m) + ρ(2m + 1) up to the first that is not positive, each capped at the one before,
    τ = 2 Σ Γₘ − 1. At most 1; 1 for fewer than 4 samples or a constant series. For an AR(1)
    series of coefficient φ it tends to (1 − φ) / (1 + φ)."""
    rho = autocorrelation(series)
    n = len(rho)
    if n < 4 or rho[0] == 0.0:
        return 1.0
    tau, cap = -1.0, math.inf
    for m in range((n - 1) // 2):
        pair = float(rho[2 * m] + rho[2 * m + 1])
        if pair <= 0.0:
            break
        cap = min(cap, pair)
        tau += 2.0 * cap
    return min(1.0, 1.0 / tau) if tau > 0.0 else 1.0


def mass_within(
    particles: FloatArray, weights: FloatArray, x_m: float, y_m: float, radius_m: float
) -> float:
    """The weight of the particles whose (x₀, y₀) lie within ``radius_m`` of (x, y)."""
    inside = np.hypot(particles[:, 0] - x_m, particles[:, 1] - y_m) <= radius_m
    return float(weights[inside].sum())


class WindowMean(NamedTuple):
    """A window of readings as the filter takes it: the reading positions, the mean reading,
    the mean wind (east, north) and whether any reading was a detection."""

    points: list[tuple[float, float, float]]
    value_g_m3: float
    wind: tuple[float, float]
    detected: bool


@dataclass(eq=False)
class SourceTermFilter(SavesState):
    """The estimator alone: particles (x₀, y₀, Q) and their weights, updated reading by reading.

    Its state is the particles and weights (``rng`` is the behaviour's generator, saved with it).
    """

    state_attributes = ("particles", "weights")

    particles: FloatArray  # (n, 3): x0, y0, Q
    curves: DispersionCurves
    release_height_m: float
    rng: np.random.Generator
    log_sigma: float = 0.6
    floor_g_m3: float = 1e-4
    jitter: float = 0.1
    prior: Callable[[int], FloatArray] | None = None
    detect_g_m3: float = PLUME_THRESHOLD_G_M3
    detect_scale_g_m3: float = PLUME_THRESHOLD_G_M3
    background_probability: float = 0.01
    miss_probability: float = 0.3
    #: Each window's log-likelihood is multiplied by this (its weight as evidence): 1 treats
    #: every window as independent; below 1 it counts correlated windows as fewer.
    tempering: float = 1.0
    #: Resample when the effective sample size is below this fraction of the particles.
    resample_below: float = 0.5
    weights: FloatArray = field(init=False)
    # below this for every particle, a reading is unexplained: ln of the 3σ magnitude
    # floor times a 2 % detection probability (twice the background)
    redraw_log_likelihood: ClassVar[float] = -4.5 + math.log(0.02)

    def __post_init__(self) -> None:
        self.particles = np.array(self.particles, dtype=np.float64)
        self.weights = np.full(len(self.particles), 1.0 / len(self.particles))

    def predict(
        self,
        x_m: float | FloatArray,
        y_m: float | FloatArray,
        z_m: float | FloatArray,
        wind: tuple[float, float],
    ) -> FloatArray:
        """Each particle's predicted concentration at (x, y, z) in the wind (east, north); for
        arrays of points (shape (k, 1)), a (k, particles) array."""
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

    def detection_probability(self, predicted: FloatArray) -> FloatArray:
        """P(detection | each predicted mean c) of :meth:`log_likelihood`."""
        scale = self.detect_scale_g_m3
        p_det = self.background_probability + (1.0 - self.background_probability) * (
            -np.expm1(-predicted / scale)
        )
        return np.asarray(np.minimum(p_det, 1.0 - self.miss_probability))

    def log_likelihood(
        self, predicted: FloatArray, value_g_m3: float, detected: bool | None = None
    ) -> FloatArray:
        """ln p(reading | each particle's predicted mean): zero-inflated (Hutchinson et al.).

        The reading is a *detection* when ``detected`` says so (default: it is at least
        ``detect_g_m3``; a window's mean is a detection when any of its samples was).
        P(detection | c) =
        p_bg + (1 − p_bg)(1 − exp(−c / ``detect_scale_g_m3``)), at most 1 − p_miss:
        ``background_probability`` p_bg is a false hit where the model has no gas,
        ``miss_probability`` p_miss a miss where the model has gas (an intermittent plume's
        blanks). A non-detection has likelihood 1 − P(detection | c); a detection P(detection |
        c) times the magnitude term exp(−r²/2σ²), r = ln(y + ε) − ln(c + ε), floored at r = 3σ
        (a filament peak far above the mean is not evidence against the particle).
        """
        p_det = self.detection_probability(predicted)
        if not (value_g_m3 >= self.detect_g_m3 if detected is None else detected):
            return np.asarray(np.log1p(-p_det))
        eps = self.floor_g_m3
        residual = np.log(value_g_m3 + eps) - np.log(predicted + eps)
        magnitude = -0.5 * np.minimum((residual / self.log_sigma) ** 2, 9.0)
        return np.asarray(np.log(p_det) + magnitude)

    def update(
        self, x_m: float, y_m: float, z_m: float, value_g_m3: float, wind: tuple[float, float]
    ) -> None:
        """One reading at (x, y, z)."""
        self.update_mean([(x_m, y_m, z_m)], value_g_m3, wind)

    def predict_mean(
        self, points: Sequence[tuple[float, float, float]], wind: tuple[float, float]
    ) -> FloatArray:
        """Each particle's predicted concentration averaged over ``points``."""
        total = np.zeros(len(self.particles))
        for x, y, z in points:
            total += self.predict(x, y, z, wind)
        return total / len(points)

    def update_mean(
        self,
        points: Sequence[tuple[float, float, float]],
        value_g_m3: float,
        wind: tuple[float, float],
        detected: bool | None = None,
    ) -> None:
        """The mean ``value_g_m3`` of readings taken at ``points`` (a window), against each
        particle's prediction averaged over the same points."""
        predicted = self.predict_mean(points, wind)
        log_l = self.log_likelihood(predicted, value_g_m3, detected)
        if self.prior is not None and log_l.max() < self.redraw_log_likelihood:
            # No particle explains this reading: the cloud has collapsed on a wrong source.
            # Redraw a fifth of it from the prior so the filter can recover.
            fresh = self.rng.random(len(self.particles)) < 0.2
            self.particles[fresh] = self.prior(int(fresh.sum()))
            predicted[fresh] = self.predict_mean(points, wind)[fresh]
            log_l = self.log_likelihood(predicted, value_g_m3, detected)
        if self.tempering != 1.0:
            log_l = self.tempering * log_l
        log_w = np.log(self.weights + 1e-300) + log_l
        log_w -= log_w.max()
        w = np.exp(log_w)
        self.weights = w / w.sum()
        if 1.0 / float(np.sum(self.weights**2)) < self.resample_below * len(self.weights):
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


class ParticleFilter(SeekingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    # ``filter`` is rebuilt from ``prior_origin`` (where its prior was drawn) on restore;
    # ``rng`` is the context's generator, which the autopilot saves on its own.
    own_state: ClassVar[tuple[str, ...]] = (
        "prior_origin",
        "window",
        "window_wind",
        "window_start_s",
        "detected",
        "probe_side",
        "sweep",
        "wind_series",
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
    declare_spread_m = 1.0
    probe_downwind_m = 4.0
    approach_spread_m = 5.0
    probe_across_m = 2.0
    threshold_g_m3 = PLUME_THRESHOLD_G_M3
    window_s = 1.0
    window_log_sigma = 1.0
    #: "independent": every window full evidence (the published tables); "effective": each
    #: window's log-likelihood × n_eff / n of the windows' winds, and the stopping rule below.
    likelihood = "independent"
    #: With ``likelihood = "effective"``: declare once this share of the weight is within
    #: ``declare_radius_m`` of the estimate (instead of ``declare_spread_m``).
    declare_mass = 0.9
    declare_radius_m = 2.0
    #: With ``likelihood = "effective"``: probe once the spread is below this (instead of
    #: ``approach_spread_m``; the tempered posterior is wider while the vehicle sweeps).
    effective_approach_spread_m = 20.0

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        if self.likelihood not in LIKELIHOODS:
            raise FieldError(
                type(self).__name__,
                "likelihood",
                f"{self.likelihood!r}: valid: {', '.join(LIKELIHOODS)}",
            )
        self.rng = ctx.rng
        self.wind_series: list[tuple[float, float]] = []  # each window's mean wind ("effective")
        plume = ctx.scenario.plume
        self.curves = dispersion_curves(plume.coefficients, plume.stability)
        self.release_height_m = plume.sources[0].release_height_m
        self.filter: SourceTermFilter | None = None
        self.prior_origin: tuple[tuple[float, float], float, float] | None = None  # wind, x, y
        self.detected = False
        self.window: list[tuple[float, float, float, float]] = []  # x, y, z, reading
        self.window_wind: list[tuple[float, float]] = []
        self.window_start_s: float | None = None
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

    def checkpoint(self) -> dict[str, Any]:
        data = super().checkpoint()
        data["filter"] = None if self.filter is None else self.filter.checkpoint()
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
        return SourceTermFilter(
            start,
            self.curves,
            self.release_height_m,
            self.rng,
            log_sigma=self.window_log_sigma,
            prior=draw,
        )

    def _average(
        self, now_s: float, readings: Sequence[ConcentrationReading], wind: tuple[float, float]
    ) -> None:
        """Add the readings and the wind to the window; every ``window_s`` update the filter
        once with the window's mean reading against the particles' predictions averaged over
        the window's reading positions, in the window's mean wind (a detection if any of its
        readings was at least the threshold)."""
        if self.window_start_s is None:
            self.window_start_s = now_s
        self.window_wind.append(wind)
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            self.detected = self.detected or r.reported_g_m3 >= self.threshold_g_m3
            self.window.append((*r.position_enu_m, r.reported_g_m3))
        if now_s - self.window_start_s < self.window_s or not self.window:
            return
        assert self.filter is not None
        points = [(x, y, z) for x, y, z, _ in self.window]
        values = [v for *_, v in self.window]
        n = len(self.window_wind)
        mean_wind = (
            sum(w[0] for w in self.window_wind) / n,
            sum(w[1] for w in self.window_wind) / n,
        )
        detected = max(values) >= self.threshold_g_m3
        self._update(now_s, WindowMean(points, sum(values) / len(values), mean_wind, detected))
        self.window, self.window_wind, self.window_start_s = [], [], None

    def _update(self, now_s: float, window: WindowMean) -> None:
        """One window into the filter (a cooperative subclass also shares it)."""
        assert self.filter is not None
        if self.likelihood == "effective":
            self.filter.tempering = self._online_tempering(window.wind)
        self.filter.update_mean(*window)

    def _online_tempering(self, wind: tuple[float, float]) -> float:
        """The weight of the window whose mean anemometer wind is ``wind``: n_eff / n of the
        series of the windows' mean winds so far, this one included (:func:`effective_fraction`)."""
        self.wind_series.append(wind)
        return effective_fraction(self.wind_series)

    def sure(self, mx: float, my: float, spread: float) -> bool:
        """The stopping rule's test of the estimate (mx, my) of ``spread``."""
        if self.likelihood != "effective":
            return spread < self.declare_spread_m
        assert self.filter is not None
        f = self.filter
        return (
            mass_within(f.particles, f.weights, mx, my, self.declare_radius_m) >= self.declare_mass
        )

    def seek(self, step: SeekStep) -> Setpoint | None:
        own, readings, wind_read = step.own, step.readings, step.wind
        x, y, _ = own.position_enu_m
        wind, frame = wind_read.vector_m_s, wind_read.frame
        if self.filter is None:
            self.prior_origin = (wind, x, y)
            self.filter = self._new_filter(frame, x, y)
        self._average(own.sim_time_s, readings, wind)
        mx, my, q, spread = self.filter.estimate()
        near = math.hypot(mx - x, my - y) <= self.probe_downwind_m + self.probe_across_m + 1.0
        if self.detected and near and self.sure(mx, my, spread):
            self.declaration = SourceEstimate(
                x_m=mx, y_m=my, sim_time_s=own.sim_time_s, release_rate_g_s=q, spread_m=spread
            )
            return None
        approach = (
            self.effective_approach_spread_m
            if self.likelihood == "effective"
            else self.approach_spread_m
        )
        if self.detected and spread < approach:
            return fly(own, self._probe_velocity(own, frame, mx, my), self.altitude)
        return fly(own, self.sweep.velocity(frame, x, y), self.altitude)
