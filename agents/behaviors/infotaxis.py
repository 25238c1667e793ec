"""Infotaxis for an intermittent plume: move where the expected information about the source is
greatest (Vergassola, Villermaux & Shraiman 2007, Nature 445:406), with an encounter model
made from the plume's hit statistics.

The algorithm is :mod:`agents.behaviors.infotaxis_core`'s (checked on its own model against
Loisy & Eloy's OTTO by ``plumeswarm bench pomdp``); this class flies it. Every second (a step
of ``step_m`` at ``speed_m_s``) the searcher counts its **hits** — a detection (a reading the
scenario's :func:`~agents.behaviors.detection.detector_for` accepts) that follows a reading
without one, or a detection that has lasted another ``rearm_s`` — and updates its belief over
the source position with Bayes' rule, taking the counts as Poisson with mean r·Δt:

    r(along, across) = r_axis · exp(−across² / (2 (f·σy(along))²)) + r_background

(:class:`~agents.behaviors.infotaxis_core.PlumeEncounterModel`, along = distance downwind of
the candidate source in the mean wind, none upwind of it), the last of ``n_hits`` classes
counting "≥ n_hits − 1", P(no hit) never below ``miss_floor``, and each step's evidence
weighed by ``evidence_weight`` (the likelihood raised to that power). Then it moves (upwind,
downwind, left, right by ``step_m``, or stays) to minimise the expected entropy.

**The encounter model's input.** ``hit_statistics`` (a
:class:`~agents.behaviors.infotaxis_core.PlumeHitStatistics`: P(hit within 1 s) on the axis
and its crosswind width at distances downwind, as measured in an environment) fixes the model
(:func:`~agents.behaviors.infotaxis_core.model_from_statistics`); a subclass for a calibrated
environment sets it. Without it the model is estimated online: the belief is over (source
cell, hypothesis), the hypotheses being every pair of an axis rate in ``axis_rates_hz`` and a
width factor f in ``width_factors`` applied to the scenario's plume σy (its dispersion family
and stability class, fitted as σy = k·x at 30, 50 and 80 m), so the hits select the rate and
the width along with the source.

**The concentration likelihood** (``likelihood = "concentration"``;
:class:`ConcentrationInfotaxis`; the default ``"hits"`` is the model above). The step's
observation is the class of its mean reading m (``concentration_classes`` 7: m below
``threshold_g_m3``, then bins a factor ``class_factor`` √10 wide, the last open), and its
likelihood is that of m given the mean plume of a source in the cell
(:func:`~agents.behaviors.infotaxis_core.unit_plume_g_m3` × a release rate, released at the
searcher's height, in the mean wind, the scenario's σy and σz no narrower than a cell, σz
widened to √(σz² + s²) for a release height unknown by s = ``release_height_spread_m`` 3 m):
a stray reading with probability ``stray_probability`` 0.02, else zero with probability
1 − γ and gamma-distributed with mean c̄/γ and shape k with probability γ
(:func:`~agents.behaviors.infotaxis_core.concentration_likelihoods`). The belief is over
(cell, rate in ``release_rates_g_s``, (γ, k) in ``regimes``): (1, 4) a steady plume, (0.5, 1)
and (0.15, 1) an intermittent one. Each step's likelihood is raised to
``concentration_evidence_weight`` 0.5 (consecutive steps of a meandering plume are
correlated). A confident belief is declared only from a step with a reading over the
threshold ``concentration_confirm_m`` 1 m (a cell) downwind of its mean, where a source
there sends gas without a break; the searcher does not stay put
(``concentration_may_stay`` false: standing in a blank of a meandering plume, each blank
favours its own place). docs/gsl.md "The concentration likelihood" has where each
value comes from and its tuning measurement.

**Declaration by evidence**: when the belief's mass (over every hypothesis) within
``declare_radius_m`` of its mean reaches ``declare_mass``, it declares the mean (spread: the
belief's standard deviation) and holds there. Use
``behavior = "agents.behaviors.infotaxis:Infotaxis"``.

**The parameters and the plume statistic each comes from** (the calibrated plume: σy 2.4, 4.0,
6.3 m at 30, 50, 80 m in a 6 m/s wind; the filament plume: P(hit within 1 s) ≈ 0.75 on its
axis, ≈ 0 at 4 m):

- ``cell_m`` 1 m: below half the narrowest σy searched (2.4 m at 30 m), so the belief
  resolves the plume's width where it starts.
- ``step_m`` 2 m at ``speed_m_s`` 2 m/s: a step of about 1 s (1–1.4 s as the vehicle slows
  into its target; the counts' mean uses the step's measured duration), the window of the
  measured "P(hit within 1 s)", so r = −ln(1 − P) needs no conversion.
- ``rearm_s`` 1 s: a detection lasting a whole window counts again in the next, as a window
  with gas would (in a steady plume the detector stays on).
- ``n_hits`` 4 (counts 0, 1, 2, ≥ 3 in a step): Loisy & Eloy's cap ⌈μ + √μ⌉ + 1 for the
  largest axis mean hits the model allows in a step, μ = 1.4 (r for P = 0.75).
- ``miss_floor`` 0.25: the plume leaves a searcher on its axis without a hit in 1 s a
  quarter of the time (1 − 0.75), so no model cell may predict a miss as less likely than that.
- ``background_hz`` 0.02 /s: a hit where the model predicts none costs a cell a factor
  ≈ 0.02·Δt / (r·Δt), never 0 (a stray filament, a noisy sample).
- ``axis_rates_hz`` 0.3, 1, 3 /s (P(hit within 1 s) 0.26, 0.63, 0.95): from the sparse
  bursts of a meandering plume (5–9 % of samples with gas on the axis of the small meander)
  through a detector that stays on (1 /s with ``rearm_s``) and the filament plume's axis
  (P = 0.75, 1.4 /s) to denser bursts.
- ``width_factors`` 0.3, 1: the filament plume without meander is ≈ 1 m wide at the starts
  (0.2–0.4 σy there); the calibrated meandering plume's hits spread as σy.
- ``near_source_m`` 10 m: the meander moves the centreline by about σv·t, 0.5–1.4 m/s ×
  1.7 s ≤ 2.4 m over the first 10 m of a 6 m/s wind, no more than the plume's own width
  there: nearer than that the plume is continuous on its axis, so the axis rate grows as
  10 m / along (and P(no hit) reaches the floor). Without it a burst of hits is best
  explained by a source just upwind of where it came, whose narrow plume no miss beside it
  contradicts (tuning seeds ≥ 1000, meander_small: median final error 26 m with it, 50 m
  without).
- ``evidence_weight`` 0.5: each step's likelihood is raised to this power before Bayes'
  rule. In a meandering plume hits come in bursts while the wandering centreline sweeps over
  the searcher, correlated over seconds, not independently as the Poisson model has them;
  a 1 s step counts as half an independent observation (tuning seeds ≥ 1000, runs 0–5:
  meander_small 4 false declarations of 6 → 0, median final error 26 → 9.7 m; steady plume
  3 of 6 within 2 m either way).
- ``declare_radius_m`` 2 m (the success radius), ``declare_mass`` 0.9 (0.6 declared in 5 of 6
  runs in the steady plume, none within 2 m; tuning seeds ≥ 1000); the box: 100 m
  upwind, 20 m downwind, ±40 m across of the start (the starts are 30–80 m downwind, ±20 m
  across).
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3, detector_for
from agents.behaviors.infotaxis_core import (
    FloatArray,
    IntArray,
    PlumeEncounterModel,
    PlumeHitStatistics,
    SharedArrays,
    SparseLikelihoods,
    bayes_update,
    choose_move,
    concentration_class,
    concentration_edges,
    concentration_likelihoods,
    expected_entropy_shared,
    expected_entropy_sparse,
    hit_likelihoods,
    model_from_statistics,
    unit_plume_g_m3,
    width_slope,
)
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import fly, toward
from agents.behaviors.wind import WindFrame
from swarmbus.errors import FieldError
from swarmbus.messages import ConcentrationReading, Setpoint

if TYPE_CHECKING:
    from plume_atmosphere.dispersion import DispersionCurves

#: Cells whose belief is below this fraction of the largest are left out of the move choice.
SUPPORT_FLOOR = 1e-12
#: Distances (m) downwind at which the scenario's σy is fitted: the bench's start distances.
WIDTH_FIT_DISTANCES_M = (30.0, 50.0, 80.0)


def scenario_curves(ctx: BehaviorContext) -> DispersionCurves:
    """σy(x), σz(x) of the scenario's plume (its dispersion family and stability class)."""
    from plume_atmosphere.dispersion import dispersion_curves

    plume = ctx.scenario.plume
    return dispersion_curves(plume.coefficients, plume.stability)


def scenario_width_slope(ctx: BehaviorContext) -> float:
    """k of σy ≈ k·x for the scenario's plume (its dispersion family and stability class)."""
    sigma_y, _ = scenario_curves(ctx).sigmas(np.array(WIDTH_FIT_DISTANCES_M))
    return width_slope(WIDTH_FIT_DISTANCES_M, list(sigma_y))


@functools.lru_cache(maxsize=256)
def _background_classes(
    dt_s: float, background_hz: float, n_hits: int, miss_floor: float
) -> FloatArray:
    """The hit classes of the background alone in a step of ``dt_s``: a pure function, kept
    out of the behaviour's state (a restored behaviour computes the same bits), read-only."""
    classes = hit_likelihoods(np.array([background_hz * dt_s]), n_hits, miss_floor)[:, 0]
    classes.setflags(write=False)
    return classes


class Infotaxis(SeekingBehavior):
    ignores_peers = True  # reads neither its peers' states nor their readings: any radio
    # ``cells_xy`` is rebuilt from ``grid_origin`` (where the grid was laid) on restore
    own_state: ClassVar[tuple[str, ...]] = (
        "detector",
        "grid_origin",
        "belief",
        "target_xy",
        "step_started_s",
        "hits",
        "detecting_since_s",
        "observed_xy",
        "wind_sum",
        "concentration_sum",
        "search_z_m",
    )
    cell_m = 1.0
    step_m = 2.0
    speed_m_s = 2.0
    prior_upwind_m = 100.0
    prior_downwind_m = 20.0
    prior_half_width_m = 40.0
    rearm_s = 1.0
    n_hits = 4
    miss_floor = 0.25
    background_hz = 0.02
    axis_rates_hz: tuple[float, ...] = (0.3, 1.0, 3.0)
    width_factors: tuple[float, ...] = (0.3, 1.0)
    hit_statistics: ClassVar[PlumeHitStatistics | None] = None
    threshold_g_m3 = PLUME_THRESHOLD_G_M3
    near_source_m = 10.0
    evidence_weight = 0.5
    declare_radius_m = 2.0
    declare_mass = 0.9
    #: The observation model: "hits" (the encounter model above) or "concentration" (the
    #: step's mean reading against the mean plume, :meth:`_concentration_at`).
    likelihood = "hits"
    release_rates_g_s: tuple[float, ...] = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
    regimes: tuple[tuple[float, int], ...] = ((1.0, 4), (0.5, 1), (0.15, 1))
    concentration_classes = 7
    class_factor = math.sqrt(10.0)
    stray_probability = 0.02
    concentration_evidence_weight = 0.5
    concentration_confirm_m = 1.0
    release_height_spread_m = 3.0
    concentration_may_stay = False

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.detector = detector_for(ctx, self.threshold_g_m3)
        if self.likelihood not in ("hits", "concentration"):
            raise FieldError(
                type(self).__name__,
                "likelihood",
                f"{self.likelihood!r}: valid: hits, concentration",
            )
        self.concentration = self.likelihood == "concentration"
        if self.concentration:
            self.evidence_weight = self.concentration_evidence_weight
            self.curves = scenario_curves(ctx)
            self.edges = concentration_edges(
                self.threshold_g_m3, self.class_factor, self.concentration_classes
            )
        self.models = self._models(ctx)
        self.cells_xy: FloatArray | None = None  # (n, 2) ENU centres
        self._box = (np.zeros(2), np.zeros(2))  # the cells' least and greatest east, north
        self.grid_origin: tuple[tuple[float, float], float, float] | None = None  # wind, x, y
        self.belief: FloatArray | None = None  # (models, cells)
        self.target_xy: tuple[float, float] | None = None
        self.step_started_s = 0.0
        self.hits = 0
        self.detecting_since_s: float | None = None
        self.observed_xy = (0.0, 0.0, 0.0)  # Σx, Σy, n of this step's readings
        self.wind_sum = (0.0, 0.0, 0.0)  # Σ east, Σ north, n: the mean wind of the search
        self.concentration_sum = (0.0, 0.0, 0)  # Σ reading, Σ height, n of this step's readings
        self.search_z_m: float | None = None  # the height of the last step's readings

    def _models(self, ctx: BehaviorContext) -> list[Any]:
        if self.concentration:  # (release rate, intermittency, shape) hypotheses
            return [
                (q, gamma, shape) for gamma, shape in self.regimes for q in self.release_rates_g_s
            ]
        width_min_m = self.cell_m
        if self.hit_statistics is not None:
            return [
                model_from_statistics(
                    self.hit_statistics, width_min_m, self.background_hz, self.near_source_m
                )
            ]
        slope = scenario_width_slope(ctx)
        return [
            PlumeEncounterModel(
                axis_rate_hz=rate,
                axis_ref_m=1.0,
                axis_decay=0.0,
                width_slope=factor * slope,
                width_min_m=width_min_m,
                background_hz=self.background_hz,
                near_source_m=self.near_source_m,
            )
            for rate in self.axis_rates_hz
            for factor in self.width_factors
        ]

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
        self._box = (self.cells_xy.min(axis=0), self.cells_xy.max(axis=0))
        self.belief = np.full((len(self.models), a.size), 1.0 / (len(self.models) * a.size))

    def mean_wind(self) -> WindFrame:
        e, n, k = self.wind_sum
        return WindFrame.of((e / k, n / k))

    def likelihoods(
        self, frame: WindFrame, x: float, y: float, dt_s: float, cells: IntArray | None = None
    ) -> FloatArray:
        """P(h hits at (x, y) in dt | model, source cell): shape (n_hits, models, cells), for
        every cell or the ``cells`` given."""
        return self.sparse_likelihoods(frame, x, y, dt_s, cells).dense()

    def sparse_likelihoods(
        self, frame: WindFrame, x: float, y: float, dt_s: float, cells: IntArray | None = None
    ) -> SparseLikelihoods:
        """:meth:`likelihoods` as the background's classes and each model's cells its plume
        reaches."""
        assert self.cells_xy is not None
        xy = self.cells_xy if cells is None else self.cells_xy[cells]
        return self._sparse_at(xy, frame, x, y, dt_s)

    def _sparse_at(
        self, xy: FloatArray, frame: WindFrame, x: float, y: float, dt_s: float
    ) -> SparseLikelihoods:
        """:meth:`sparse_likelihoods` for the cells whose centres are ``xy``."""
        if self.concentration:
            return self._concentration_at(xy, frame, x, y)
        # Only cells whose plume reaches (x, y) need the Poisson classes; the others see the
        # background's. Those are downwind of (x, y)'s source cells (along > 0), where
        # :meth:`PlumeEncounterModel.plume_cells` is its crosswind test alone; the models
        # that share a width share that support.
        downwind, along, across = _upwind_cells(xy, frame, x, y)
        # per width: its plume cells, their (along, across) and the models' shared arrays
        supports: dict[tuple[float, float], tuple[IntArray, FloatArray, FloatArray, SharedArrays]]
        supports = {}
        inside: list[IntArray] = []
        means: list[FloatArray] = []
        for m in self.models:
            width = (m.width_slope, m.width_min_m)
            if width not in supports:
                u2 = m.crosswind_u2(along, across)
                keep = np.flatnonzero(u2 < 36.0)
                shared: SharedArrays = {m.shape_key(): np.exp(-0.5 * u2[keep])}
                supports[width] = (downwind[keep], along[keep], across[keep], shared)
            cells, a, c, shared = supports[width]
            inside.append(cells)
            means.append(m.plume_mean_hits(a, c, dt_s, shared))
        # one call for every model's cells: the classes are computed point by point
        return SparseLikelihoods(
            background=self._background_classes(dt_s),
            inside=tuple(inside),
            classes=hit_likelihoods(np.concatenate(means), self.n_hits, self.miss_floor),
            offsets=(0, *itertools.accumulate(len(i) for i in inside)),
            cells=xy.shape[0],
        )

    def _concentration_at(
        self, xy: FloatArray, frame: WindFrame, x: float, y: float
    ) -> SparseLikelihoods:
        """P(the step's mean reading at (x, y) is in each class | (release rate, intermittency,
        shape), source cell) for the cells centred at ``xy``: the mean plume of a source there
        (:func:`~agents.behaviors.infotaxis_core.unit_plume_g_m3` × the rate, in the mean
        wind, the scenario's σy and σz no narrower than a cell, σz widened to
        √(σz² + s²) by a release height unknown by s = ``release_height_spread_m`` about the
        searcher's: the Gaussian's average over such heights) through
        :func:`~agents.behaviors.infotaxis_core.concentration_likelihoods`. The cells whose
        plume reaches (x, y) (downwind of them, within 6 σy across) are every model's; the
        others see the stray readings alone."""
        downwind, along, across = _upwind_cells(xy, frame, x, y)
        sigma_y, sigma_z = self.curves.sigmas(along)
        sigma_y = np.maximum(sigma_y, self.cell_m)
        keep = np.flatnonzero((across / sigma_y) ** 2 < 36.0)
        cells = downwind[keep]
        height = self.search_z_m if self.search_z_m is not None else self.altitude_m or 0.0
        unit = unit_plume_g_m3(
            along[keep],
            across[keep],
            height,
            max(frame.speed_m_s, 0.1),
            sigma_y[keep],
            np.hypot(np.maximum(sigma_z[keep], self.cell_m), self.release_height_spread_m),
        )
        # where even the largest rate's mean c̄ is below threshold·min(k·γ)/30, every regime
        # reaches the threshold with probability γ·e^(−x)·Σ_{i<k} x^i/i! (x ≥ 30) < 1e-9:
        # those cells see the strays alone
        floor = self.threshold_g_m3 * min(g * k for g, k in self.regimes) / 30.0
        reach = np.flatnonzero(unit * max(self.release_rates_g_s) >= floor)
        cells, unit = cells[reach], unit[reach]
        classes = [
            concentration_likelihoods(q * unit, gamma, shape, self.edges, self.stray_probability)
            for q, gamma, shape in self.models
        ]
        return SparseLikelihoods(
            background=self._background_classes(1.0),
            inside=tuple(cells for _ in self.models),
            classes=np.concatenate(classes, axis=1),
            offsets=tuple(k * cells.size for k in range(len(self.models) + 1)),
            cells=xy.shape[0],
        )

    def _background_classes(self, dt_s: float) -> FloatArray:
        """The hit classes of the background alone in a step of ``dt_s`` (every place of a
        decision asks for the same step)."""
        if self.concentration:
            return _stray_classes(tuple(self.edges), self.stray_probability)
        return _background_classes(dt_s, self.background_hz, self.n_hits, self.miss_floor)

    def _observe(self, readings: Sequence[ConcentrationReading]) -> None:
        sx, sy, n = self.observed_xy
        sc, sz, nc = self.concentration_sum
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            sx, sy, n = sx + r.position_enu_m[0], sy + r.position_enu_m[1], n + 1
            sc, sz, nc = sc + r.reported_g_m3, sz + r.position_enu_m[2], nc + 1
            if not self.detector.hit(r.reported_g_m3):
                self.detecting_since_s = None
            elif (
                self.detecting_since_s is None
                or r.sim_time_s - self.detecting_since_s >= self.rearm_s
            ):
                self.hits += 1
                self.detecting_since_s = r.sim_time_s
        self.observed_xy = (sx, sy, n)
        self.concentration_sum = (sc, sz, nc)

    @property
    def n_classes(self) -> int:
        """How many observation classes a step has."""
        return self.concentration_classes if self.concentration else self.n_hits

    def observation(self) -> int:
        """This step's observation: its hits, or the class of its mean reading."""
        if not self.concentration:
            return self.hits
        sc, _, nc = self.concentration_sum
        mean = sc / nc if nc else 0.0
        return concentration_class(
            mean, self.threshold_g_m3, self.class_factor, self.concentration_classes
        )

    def _near(self, xy: FloatArray, x: float, y: float, radius_m: float) -> IntArray:
        """Which of the cells centred at ``xy`` lie within ``radius_m`` of (x, y) (indices,
        ascending). A cell within the radius is within it on each axis (the hypotenuse is
        at least either side), so only those are measured."""
        dx = xy[:, 0] - x
        dy = xy[:, 1] - y
        box = np.flatnonzero((np.abs(dx) <= radius_m) & (np.abs(dy) <= radius_m))
        return box[np.hypot(dx[box], dy[box]) <= radius_m]

    def _decide(self, frame: WindFrame, x: float, y: float, dt_s: float) -> tuple[float, float]:
        places = self._places(frame, x, y)
        return places[choose_move(self._scores(frame, places, dt_s))]

    def _places(self, frame: WindFrame, x: float, y: float) -> list[tuple[float, float]]:
        """Where the next step may go: stay, then upwind, downwind, left, right by ``step_m``
        (those inside the grid)."""
        assert self.cells_xy is not None
        lo, hi = self._box
        s = self.step_m
        places = [(x, y)]
        for a, c in _DIRECTIONS:
            mx, my = frame.velocity(a * s, c * s)
            if lo[0] <= x + mx <= hi[0] and lo[1] <= y + my <= hi[1]:
                places.append((x + mx, y + my))
        if self.concentration and not self.concentration_may_stay and len(places) > 1:
            return places[1:]
        return places

    def _scores(
        self, frame: WindFrame, places: Sequence[tuple[float, float]], dt_s: float
    ) -> list[float]:
        """The expected entropy of the belief after a step to each of ``places``."""
        assert self.cells_xy is not None and self.belief is not None
        # The choice is made on the cells the belief has not ruled out (mass above 1e-12 of
        # the largest): the rest cannot change an expected entropy by more than that.
        marginal = self.belief.sum(axis=0)
        cells = np.flatnonzero(marginal > SUPPORT_FLOOR * marginal.max())
        belief = self.belief[:, cells]
        xy = self.cells_xy[cells]
        entropy = expected_entropy_shared if self.concentration else expected_entropy_sparse
        return [
            entropy(
                belief,
                self._sparse_at(xy, frame, px, py, dt_s),
                self._near(xy, px, py, 0.5 * self.cell_m),
            )
            for px, py in places
        ]

    def _update(self, frame: WindFrame, x: float, y: float, dt_s: float) -> None:
        assert self.belief is not None
        self.belief = bayes_update(self.belief, self._own_likelihood(frame, x, y, dt_s), None)
        self._next_step()

    def _next_step(self) -> None:
        """Forget the step just applied."""
        self.hits = 0
        self.observed_xy = (0.0, 0.0, 0.0)
        _, sz, nc = self.concentration_sum
        if nc:
            self.search_z_m = sz / nc
        self.concentration_sum = (0.0, 0.0, 0)

    def _observed_at(self, x: float, y: float) -> tuple[float, float]:
        """Where this step observed: the mean position of its readings ((x, y) if none)."""
        sx, sy, n = self.observed_xy
        return (sx / n, sy / n) if n else (x, y)

    def _own_likelihood(self, frame: WindFrame, x: float, y: float, dt_s: float) -> FloatArray:
        """This step's likelihood of its hits per (model, cell), weighed by
        ``evidence_weight``."""
        ox, oy = self._observed_at(x, y)
        likelihood = self.sparse_likelihoods(frame, ox, oy, dt_s).row(
            min(self.observation(), self.n_classes - 1)
        )
        if self.evidence_weight != 1.0:
            likelihood = likelihood**self.evidence_weight
        return np.asarray(likelihood)

    def _belief_mean(self) -> tuple[float, float, float, float]:
        """Mean (x, y), spread and the mass within ``declare_radius_m`` of the mean."""
        assert self.belief is not None and self.cells_xy is not None
        cells = self.belief.sum(axis=0)
        mean = cells @ self.cells_xy
        var = cells @ ((self.cells_xy - mean) ** 2)
        near = self._near(self.cells_xy, float(mean[0]), float(mean[1]), self.declare_radius_m)
        return float(mean[0]), float(mean[1]), float(math.sqrt(var.sum())), float(cells[near].sum())

    def seek(self, step: SeekStep) -> Setpoint | None:
        own, readings, wind_read = step.own, step.readings, step.wind
        x, y, _ = own.position_enu_m
        now = own.sim_time_s
        wind = wind_read.vector_m_s
        e, n, k = self.wind_sum
        self.wind_sum = (e + wind[0], n + wind[1], k + 1.0)
        frame = self.mean_wind()
        if self.belief is None:
            self.grid_origin = (wind, x, y)
            self._build_grid(frame, x, y)
            self.step_started_s = now
        self._observe(readings)
        step_dt = self.step_m / self.speed_m_s
        elapsed = now - self.step_started_s
        if self.target_xy is None:
            self.target_xy = self._decide(frame, x, y, step_dt)
        arrived = math.dist((x, y), self.target_xy) < 0.5
        if (arrived and elapsed >= step_dt) or elapsed > 3.0 * step_dt:
            detected = self.concentration and self.observation() > 0
            self._update(frame, x, y, elapsed)
            self.step_started_s = now
            mx, my, spread, mass = self._belief_mean()
            sure = mass >= self.declare_mass
            if not self.concentration:
                if sure:
                    self.declaration = SourceEstimate(
                        x_m=mx, y_m=my, sim_time_s=now, spread_m=spread
                    )
                    return None
                self.target_xy = self._decide(frame, x, y, step_dt)
            elif sure:
                # A confident belief is checked where it points: just downwind of its mean,
                # where a source there sends gas without a break, it declares on a step with
                # a reading over the threshold; a blank there is evidence like any other.
                dx, dy = frame.velocity(self.concentration_confirm_m, 0.0)
                self.target_xy = (mx + dx, my + dy)
                if detected and math.dist((x, y), self.target_xy) <= self.cell_m:
                    self.declaration = SourceEstimate(
                        x_m=mx, y_m=my, sim_time_s=now, spread_m=spread
                    )
                    return None
            else:
                self.target_xy = self._decide(frame, x, y, step_dt)
        return fly(own, toward(own, *self.target_xy, self.speed_m_s), self.altitude)


def _upwind_cells(
    xy: FloatArray, frame: WindFrame, x: float, y: float
) -> tuple[IntArray, FloatArray, FloatArray]:
    """The cells centred at ``xy`` upwind of (x, y) (indices), and (x, y)'s distance downwind
    of each and across the wind from it: where a source in the cell could send gas to (x, y)."""
    dx = x - xy[:, 0]
    dy = y - xy[:, 1]
    along = dx * frame.downwind[0] + dy * frame.downwind[1]
    downwind = np.flatnonzero(along > 0.0)
    across = dx[downwind] * frame.crosswind[0] + dy[downwind] * frame.crosswind[1]
    return downwind, along[downwind], across


class ConcentrationInfotaxis(Infotaxis):
    """:class:`Infotaxis` with ``likelihood = "concentration"``: use
    ``behavior = "agents.behaviors.infotaxis:ConcentrationInfotaxis"``, or on the bench
    ``--algorithms infotaxis_c=agents.behaviors.infotaxis:ConcentrationInfotaxis``."""

    likelihood = "concentration"


@functools.lru_cache(maxsize=16)
def _stray_classes(edges: tuple[float, ...], stray_probability: float) -> FloatArray:
    """The classes of a step's mean reading where the mean plume has no gas: the stray
    readings of :func:`~agents.behaviors.infotaxis_core.concentration_likelihoods` alone;
    read-only."""
    classes = concentration_likelihoods(np.zeros(1), 1.0, 1, np.asarray(edges), stray_probability)[
        :, 0
    ]
    classes.setflags(write=False)
    return classes


# (along, across) unit moves: upwind, downwind, left, right.
_DIRECTIONS = ((-1.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, -1.0))
