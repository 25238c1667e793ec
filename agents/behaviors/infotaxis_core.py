"""Infotaxis as pure functions: a belief over cells, hit-count likelihoods, Bayes, the move.

Nothing here knows a vehicle, a bus or a clock. A search keeps a belief ``b`` (a flat array
of probabilities, one per candidate source cell); at each decision the searcher stands
somewhere and observes a number of hits ``h``; what it knows about the plume is a table
``L[h, i] = P(h | source in cell i)`` for where it stands. Then:

- :func:`hit_likelihoods` makes ``L`` from the mean number of hits ``μ_i`` expected in the
  step if the source is in cell ``i``: Poisson counts, the last class collecting every
  count ≥ ``n_hits − 1`` (Loisy & Eloy 2022, Proc. R. Soc. A 478:20220118, §2: hits are
  Poisson with a cap), and an optional floor on the miss probability, ``P(0) ≥
  miss_floor``: a plume that is intermittent at scales the model does not resolve can give
  nothing where the model expects gas, and one such miss must not rule a cell out for good.
- :func:`bayes_update` is Bayes' rule with the cell the searcher stands on removed (it was
  not the source: the search would have ended).
- :func:`expected_entropy` is the criterion of Vergassola, Villermaux & Shraiman (2007,
  Nature 445:406, eq. 2): the entropy of the belief after the move, averaged over "the source
  is here" (entropy 0) and every hit count; :func:`choose_move` takes the candidate with the
  lowest (the first one within 1e-10 on a tie, as OTTO does).

Two encounter models give ``μ``: :func:`isotropic_mean_hits` is the source-tracking POMDP's
(Loisy & Eloy 2022 eq. 2.3–2.5, the mean hits of a searcher of radius ``a`` at distance ``r``
from a source emitting ``R`` particles per unit time that diffuse with ``D`` and live ``τ``,
``λ = √(Dτ)``), used by ``plumeswarm bench pomdp``; :class:`PlumeEncounterModel` is an
advected plume's, parametrised by the statistics a searcher meets in it (the hit rate on the
axis and the crosswind width of the hit rate against distance downwind), used by
:class:`agents.behaviors.infotaxis.Infotaxis`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]

#: Below this a probability is zero (OTTO's EPSILON).
EPSILON = 1e-10


# ------------------------------------------------------------------ the POMDP's hit model
def mu0_poisson(dims: int, lambda_over_dx: float, r_dt: float) -> float:
    """Mean hits in one step at distance λ from the source (Loisy & Eloy 2022, eq. 2.5), with
    the searcher's radius a = Δx/2 (their choice): 1D (1 − a/λ)⁻¹e⁻¹, 2D K₀(1)/ln(λ/a),
    3D (a/λ)e⁻¹, each times R·Δt."""
    from scipy.special import gamma, kn, kv

    lambda_over_a = 2.0 * lambda_over_dx
    a_over_lambda = 1.0 / lambda_over_a
    if dims == 1:
        mu0 = 1.0 / (1.0 - a_over_lambda) * math.exp(-1.0)
    elif dims == 2:
        mu0 = float(kn(0, 1.0)) / math.log(lambda_over_a)
    elif dims == 3:
        mu0 = a_over_lambda * math.exp(-1.0)
    else:
        mu0 = (
            (dims - 2)
            / float(gamma(dims / 2))
            / 2 ** (dims / 2 - 1)
            * a_over_lambda ** (dims - 2)
            * float(kv(dims / 2 - 1, 1.0))
        )
    return mu0 * r_dt


def isotropic_mean_hits(
    distance_cells: FloatArray, dims: int, lambda_over_dx: float, r_dt: float
) -> FloatArray:
    """Mean hits in one step at ``distance_cells`` (in steps Δx) from the source (Loisy & Eloy
    2022, eq. 2.4, no mean wind): μ(r) = μ₀·f(r/λ)/f(1) with f = e^(−u) (1D), K₀(u) (2D),
    e^(−u)/u (3D). A distance of 0 counts as 1 (the cell itself is handled by the caller)."""
    from scipy.special import kn, kv

    d = np.where(np.asarray(distance_cells, dtype=float) == 0.0, 1.0, distance_cells)
    u = d / lambda_over_dx
    if dims == 1:
        shape = np.exp(1.0 - u)
    elif dims == 2:
        shape = kn(0, u) / kn(0, 1.0)
    elif dims == 3:
        shape = np.exp(1.0 - u) / u
    else:
        nu = dims / 2 - 1
        shape = u ** (-nu) * kv(nu, u) / kv(nu, 1.0)
    return np.asarray(mu0_poisson(dims, lambda_over_dx, r_dt) * shape, dtype=float)


# ------------------------------------------------------------------ likelihoods and Bayes
def poisson_classes(mean_hits: FloatArray, n_hits: int) -> FloatArray:
    """P(h | μ) for h = 0 … n_hits − 1, the last class being P(h ≥ n_hits − 1); shape
    ``(n_hits, *mean_hits.shape)``."""
    mu = np.asarray(mean_hits, dtype=float)
    out = np.empty((n_hits, *mu.shape))
    if n_hits == 1:
        out[0, ...] = 1.0  # max(0, 1 − 0): every count is in the one class
        return out
    # P(h) = P(h − 1)·μ/h, each class written in place; the running sum starts at P(0) (0 + x
    # is x) and a division by 1 is skipped (x / 1 is x): the same bits as the plain recurrence
    np.exp(-mu, out=out[0, ...])
    below = out[0, ...].copy()
    for h in range(1, n_hits - 1):
        term = np.multiply(out[h - 1, ...], mu, out=out[h, ...])
        if h > 1:
            term /= h
        below += term
    np.subtract(1.0, below, out=below)
    np.maximum(0.0, below, out=out[n_hits - 1, ...])
    return out


def hit_likelihoods(mean_hits: FloatArray, n_hits: int, miss_floor: float = 0.0) -> FloatArray:
    """``L[h, i] = P(h hits | source in cell i)``: Poisson classes of :func:`poisson_classes`
    with ``P(0)`` raised to at least ``miss_floor`` (the other classes scaled down to keep the
    sum 1)."""
    table = poisson_classes(mean_hits, n_hits)
    if miss_floor > 0.0:
        p0 = table[0]
        floored = np.maximum(p0, miss_floor)
        missed = 1.0 - p0
        if missed.size and missed.min() > 0.0:  # every P(0) below 1: no division by zero
            scale = np.subtract(1.0, floored)
            scale /= missed
        else:
            with np.errstate(divide="ignore", invalid="ignore"):
                scale = np.where(p0 < 1.0, (1.0 - floored) / missed, 0.0)
        table[1:] *= scale
        table[0] = floored
    return table


def bayes_update(belief: FloatArray, likelihood: FloatArray, here: BoolArray | None) -> FloatArray:
    """Posterior after one observation whose likelihood per cell is ``likelihood``, the cells
    ``here`` (where the searcher stands; None: none) ruled out. Normalised; the prior (with
    ``here`` removed) if no cell explains the observation."""
    prior = belief.copy()
    if here is not None:
        prior[here] = 0.0
    post = prior * likelihood
    total = post.sum()
    if total > EPSILON:
        return np.asarray(post / total)
    rest = prior.sum()
    return np.asarray(prior / rest) if rest > EPSILON else belief.copy()


def entropy_bits(belief: FloatArray) -> float:
    p = belief[belief > EPSILON]
    return float(-(p * np.log2(p)).sum())


def _row_entropies_bits(joint: FloatArray, totals: FloatArray) -> FloatArray:
    """Entropy (bits) of each row of ``joint`` (rows × cells) normalised by its total:
    (Σ −j ln j)/t/ln 2 + log₂ t."""
    from scipy.special import entr

    with np.errstate(divide="ignore", invalid="ignore"):
        out = entr(joint).sum(axis=1) / totals / math.log(2.0) + np.log2(totals)
    return np.where(totals > EPSILON, out, 0.0)


def hit_probabilities(
    belief: FloatArray, likelihoods: FloatArray, here: BoolArray | None
) -> FloatArray:
    """P(h) for each hit class at a place, given the source is not in ``here``."""
    b = _given_not_in(belief, here)
    return np.asarray(likelihoods.reshape(len(likelihoods), -1) @ b.ravel())


def _given_not_in(belief: FloatArray, here: BoolArray | None) -> FloatArray:
    """A copy of ``belief`` with the cells ``here`` ruled out, normalised again (unless
    nothing is left)."""
    b = belief.copy()
    if here is not None:
        b[here] = 0.0
    total = b.sum()
    if total > EPSILON:
        b /= total
    return b


def expected_entropy(
    belief: FloatArray, likelihoods: FloatArray, here: BoolArray | None, nuisance_axes: int = 0
) -> float:
    """Expected entropy (bits) of the belief after moving to a place whose hit likelihoods are
    ``likelihoods`` (shape ``(n_hits, *belief.shape)``) and whose cells are ``here``: with
    probability ``p_end`` (the belief's mass in ``here``) the source is found (entropy 0), else
    a hit count ``h`` comes with probability P(h) and leaves the posterior of
    :func:`bayes_update`. The first ``nuisance_axes`` axes of the belief are parameters of the
    model, not the source's place: they are summed out before the entropy is taken."""
    b = belief.ravel()
    mask = None if here is None else np.broadcast_to(here, belief.shape).ravel()
    p_end = float(b[mask].sum()) if mask is not None else 0.0
    if p_end > 1.0 - EPSILON:
        return -EPSILON
    joint = likelihoods.reshape(len(likelihoods), -1) * _given_not_in(b, mask)
    if nuisance_axes:
        lead = int(np.prod(belief.shape[:nuisance_axes]))
        joint = joint.reshape(len(likelihoods), lead, -1).sum(axis=1)
    p_h = joint.sum(axis=1)
    return (1.0 - p_end) * float((p_h * _row_entropies_bits(joint, p_h)).sum())


#: A reduction over at most this many models adds them one after the other (numpy sums fewer
#: than 8 terms in order), so :func:`expected_entropy_sparse` may add them the same way.
SEQUENTIAL_SUM_MAX = 7


@dataclass(frozen=True)
class SparseLikelihoods:
    """Hit likelihoods of shape ``(n_hits, models, cells)`` that are ``background`` (n_hits,)
    except at each model's ``inside`` cells, whose classes are ``classes[:, offsets[k] :
    offsets[k + 1]]`` for model k."""

    background: FloatArray
    inside: tuple[IntArray, ...]
    classes: FloatArray
    offsets: tuple[int, ...]
    cells: int

    def dense(self) -> FloatArray:
        """The full ``(n_hits, models, cells)`` table."""
        n_hits, models = len(self.background), len(self.inside)
        table = np.empty((n_hits, models, self.cells))
        for h, value in enumerate(self.background):
            table[h].fill(value)
        places = [idx + k * self.cells for k, idx in enumerate(self.inside)]
        table.reshape(n_hits, -1)[:, np.concatenate(places)] = self.classes
        return table

    def row(self, h: int) -> FloatArray:
        """``dense()[h]``, shape ``(models, cells)``, without the other classes."""
        table = np.full((len(self.inside), self.cells), self.background[h])
        for k, idx in enumerate(self.inside):
            table[k][idx] = self.classes[h, self.offsets[k] : self.offsets[k + 1]]
        return table


def _as_mask(here: BoolArray | IntArray | None, cells: int) -> BoolArray | None:
    """``here`` as a mask over ``cells`` cells (it may be their indices)."""
    if here is None:
        return None
    if here.dtype == np.bool_:
        return np.asarray(here, dtype=np.bool_)
    mask = np.zeros(cells, dtype=bool)
    mask[here] = True
    return mask


def _ruled_out(belief: FloatArray, here: BoolArray | IntArray | None) -> tuple[FloatArray, float]:
    """A copy of ``belief`` (models, cells) with the cells ``here`` zeroed, and the mass they
    held, summed in the order a mask over the belief takes them."""
    given = belief.copy()
    if here is None:
        return given, 0.0
    if here.dtype != np.bool_ or here.ndim == 1:
        places = here if here.dtype != np.bool_ else np.flatnonzero(here)
        p_end = float(belief[:, places].ravel().sum())
        given[:, places] = 0.0
        return given, p_end
    mask = np.broadcast_to(here, belief.shape)
    p_end = float(belief[mask].sum())
    given[mask] = 0.0
    return given, p_end


def expected_entropy_sparse(
    belief: FloatArray, likelihoods: SparseLikelihoods, here: BoolArray | IntArray | None
) -> float:
    """``expected_entropy(belief, likelihoods.dense(), here, nuisance_axes=1)`` for a belief of
    shape (models, cells), bit for bit, without building the table: each model's share of
    the joint is the background's product but at its ``inside`` cells, and the shares are added
    in the order the dense sum over the models adds them. ``here`` may also be the indices of
    its cells (ascending)."""
    if belief.shape[0] > SEQUENTIAL_SUM_MAX:
        mask = _as_mask(here, belief.shape[1])
        return expected_entropy(belief, likelihoods.dense(), mask, nuisance_axes=1)
    given, p_end = _ruled_out(belief, here)
    if p_end > 1.0 - EPSILON:
        return -EPSILON
    total = given.ravel().sum()  # as the dense path sums it
    if total > EPSILON:
        given /= total
    background = likelihoods.background[:, None]
    joint = np.empty((len(likelihoods.background), belief.shape[1]))
    share = np.empty_like(joint)
    for k, inside in enumerate(likelihoods.inside):
        out = joint if k == 0 else share
        np.multiply(background, given[k], out=out)
        lo, hi = likelihoods.offsets[k], likelihoods.offsets[k + 1]
        inside_values = likelihoods.classes[:, lo:hi] * given[k, inside]
        for row, values in zip(out, inside_values, strict=True):
            row[inside] = values  # a row at a time: numpy's fast path for one index array
        if k:
            joint += share
    p_h = joint.sum(axis=1)
    return (1.0 - p_end) * float((p_h * _row_entropies_bits(joint, p_h)).sum())


def choose_move(scores: Sequence[float]) -> int:
    """The first candidate whose score is within 1e-10 of the lowest (OTTO's tie rule)."""
    arr = np.asarray(scores, dtype=float)
    return int(np.flatnonzero(np.abs(arr - arr.min()) < EPSILON)[0])


# ------------------------------------------------------------------ an advected plume's hits
#: Intermediate arrays of a computation at fixed points, by the parameters each depends on.
SharedArrays = dict[tuple[object, ...], FloatArray]


@dataclass(frozen=True)
class PlumeEncounterModel:
    """Hit rate of a searcher at (along, across) of a source in a mean wind, along downwind:

        r(along, across) = r_axis(along) · exp(−across² / (2 w(along)²)) + r_background,
        w(along) = max(width_min_m, width_slope · along),
        r_axis(along) = axis_rate_hz · (along / axis_ref_m) ^ (−axis_decay)   (along > 0),

    and no hits upwind of the source (along ≤ 0) but the background. Nearer than
    ``near_source_m`` the axis rate grows as ``near_source_m / along``: there the centreline
    has not wandered yet and the plume is continuous, so a searcher just downwind of the
    source on its axis cannot miss it for long. The hit counts in a step
    of ``dt`` are Poisson with mean ``r·dt`` (:func:`hit_likelihoods`). Each parameter is a
    statistic a searcher measures in the plume: ``axis_rate_hz`` from P(a hit within 1 s)
    on the axis at ``axis_ref_m`` (r = −ln(1 − P)), ``width_slope`` from the crosswind
    standard deviation of that probability against distance, ``axis_decay`` from how the axis
    rate falls between two distances. A cell within ``width_min_m`` across of the searcher
    near the source is not judged on a hit rate the model does not resolve.
    """

    axis_rate_hz: float
    axis_ref_m: float
    axis_decay: float
    width_slope: float
    width_min_m: float
    background_hz: float
    near_source_m: float = 0.0

    def rate_hz(self, along_m: FloatArray, across_m: FloatArray) -> FloatArray:
        along = np.asarray(along_m, dtype=float)
        downwind = along > 0.0
        safe = np.where(downwind, along, 1.0)
        width = np.maximum(self.width_min_m, self.width_slope * safe)
        near = np.maximum(safe, self.width_min_m)
        axis = self.axis_rate_hz * (near / self.axis_ref_m) ** (-self.axis_decay)
        if self.near_source_m > 0.0:
            axis = axis * np.maximum(1.0, self.near_source_m / near)
        u2 = (np.asarray(across_m) / width) ** 2
        # beyond 6 widths the plume's share is < 2e-8 of the axis rate: the background's
        rate = np.where(downwind & (u2 < 36.0), axis * np.exp(-0.5 * u2), 0.0)
        return np.asarray(rate + self.background_hz)

    def crosswind_u2(self, along_m: FloatArray, across_m: FloatArray) -> FloatArray:
        """(across / w(along))² at points downwind of the source (along > 0): the squared
        crosswind distance in plume widths, as :meth:`plume_cells` and
        :meth:`plume_mean_hits` compute it."""
        width = np.maximum(self.width_min_m, self.width_slope * along_m)
        return np.asarray((across_m / width) ** 2)

    def shape_key(self) -> tuple[object, ...]:
        """The key of the crosswind shape exp(−u²/2) in :meth:`plume_mean_hits`' ``shared``."""
        return ("shape", self.width_slope, self.width_min_m)

    def plume_cells(self, along_m: FloatArray, across_m: FloatArray) -> BoolArray:
        """Where the rate is more than the background (:meth:`rate_hz`'s support)."""
        along = np.asarray(along_m, dtype=float)
        safe = np.where(along > 0.0, along, 1.0)
        width = np.maximum(self.width_min_m, self.width_slope * safe)
        return np.asarray((along > 0.0) & ((np.asarray(across_m) / width) ** 2 < 36.0))

    def mean_hits(self, along_m: FloatArray, across_m: FloatArray, dt_s: float) -> FloatArray:
        return np.asarray(self.rate_hz(along_m, across_m) * dt_s)

    def plume_mean_hits(
        self,
        along_m: FloatArray,
        across_m: FloatArray,
        dt_s: float,
        shared: SharedArrays | None = None,
    ) -> FloatArray:
        """:meth:`mean_hits` at points of :meth:`plume_cells` only (the same operations on
        each point, without the masks that are all true there). ``shared``: the intermediate
        arrays of earlier calls at the same points, by the parameters each depends on (the
        models of one width share the crosswind shape, of one axis law the distance factor);
        filled here."""
        memo: SharedArrays = {} if shared is None else shared
        shape_key = self.shape_key()
        shape = memo.get(shape_key)
        if shape is None:
            width = np.maximum(self.width_min_m, self.width_slope * along_m)
            u2 = (across_m / width) ** 2
            shape = memo[shape_key] = np.exp(-0.5 * u2)
        near_key = ("near", self.width_min_m)
        near = memo.get(near_key)
        if near is None:
            near = memo[near_key] = np.maximum(along_m, self.width_min_m)
        decay_key = ("decay", self.width_min_m, self.axis_ref_m, self.axis_decay)
        decay = memo.get(decay_key)
        if decay is None:
            decay = memo[decay_key] = (near / self.axis_ref_m) ** (-self.axis_decay)
        axis = self.axis_rate_hz * decay
        if self.near_source_m > 0.0:
            boost_key = ("boost", self.width_min_m, self.near_source_m)
            boost = memo.get(boost_key)
            if boost is None:
                boost = memo[boost_key] = np.maximum(1.0, self.near_source_m / near)
            axis = axis * boost
        return np.asarray((axis * shape + self.background_hz) * dt_s)


@dataclass(frozen=True)
class PlumeHitStatistics:
    """What a searcher meets in a plume, measured at distances downwind on its axis: P(at least
    one hit within 1 s) there, and the crosswind standard deviation (m) of that probability."""

    distances_m: tuple[float, ...]
    axis_p_hit_1s: tuple[float, ...]
    width_m: tuple[float, ...]


def width_slope(distances_m: Sequence[float], widths_m: Sequence[float]) -> float:
    """Least-squares k of width = k·distance (a line through the source)."""
    x = np.asarray(distances_m, dtype=float)
    w = np.asarray(widths_m, dtype=float)
    return float((x * w).sum() / (x * x).sum())


def model_from_statistics(
    stats: PlumeHitStatistics,
    width_min_m: float,
    background_hz: float,
    near_source_m: float = 0.0,
) -> PlumeEncounterModel:
    """The encounter model that reproduces ``stats``: the axis rate r = −ln(1 − P) at the
    nearest distance, its power-law decay fitted in log–log through every distance, the width
    slope fitted through the source."""
    x = np.asarray(stats.distances_m, dtype=float)
    rates = -np.log1p(-np.clip(np.asarray(stats.axis_p_hit_1s, dtype=float), 0.0, 0.999))
    if len(x) > 1:
        slope = float(np.polyfit(np.log(x), np.log(np.maximum(rates, 1e-6)), 1)[0])
    else:
        slope = 0.0
    return PlumeEncounterModel(
        axis_rate_hz=float(rates[0]),
        axis_ref_m=float(x[0]),
        axis_decay=-slope,
        width_slope=width_slope(stats.distances_m, stats.width_m),
        width_min_m=width_min_m,
        background_hz=background_hz,
        near_source_m=near_source_m,
    )


def hit_statistics_from_points(
    points: Sequence[tuple[float, float, float]], p_max: float = 0.999
) -> PlumeHitStatistics:
    """:class:`PlumeHitStatistics` from P(hit within 1 s) measured at (distance downwind,
    offset across) points, as ``plumeswarm plume intermittency`` reports them: at each
    distance the axis value (the smallest offset) and the width w of the hit rate
    r = −ln(1 − P) across the wind, from its second moment over the offsets measured,
    w² = ∫ r·y² dy / ∫ r dy (trapezoids; exactly w² for r ∝ exp(−y²/2w²) sampled finely).
    P is clipped at ``p_max`` (a detector that never goes off has no finite rate)."""
    by_distance: dict[float, list[tuple[float, float]]] = {}
    for x, y, p in points:
        by_distance.setdefault(float(x), []).append((abs(float(y)), float(p)))
    distances, axis, widths = [], [], []
    for x in sorted(by_distance):
        ys, ps = (np.array(v) for v in zip(*sorted(by_distance[x]), strict=True))
        rates = -np.log1p(-np.clip(ps, 0.0, p_max))
        mass = float(np.trapezoid(rates, ys))
        if mass <= 0.0:
            continue
        distances.append(x)
        axis.append(float(ps[0]))
        widths.append(math.sqrt(float(np.trapezoid(rates * ys * ys, ys)) / mass))
    return PlumeHitStatistics(tuple(distances), tuple(axis), tuple(widths))


# ------------------------------------------------------------ a concentration sensor's readings
def concentration_edges(threshold_g_m3: float, class_factor: float, n_classes: int) -> FloatArray:
    """The lower edges of the detected classes 1 … n_classes − 1 of a step's mean reading m:
    class 0 is m < ``threshold_g_m3``, class j is threshold·f^(j−1) ≤ m < threshold·f^j, the
    last class everything from its edge up."""
    return np.asarray(threshold_g_m3 * class_factor ** np.arange(n_classes - 1), dtype=float)


def concentration_class(
    mean_g_m3: float, threshold_g_m3: float, class_factor: float, n_classes: int
) -> int:
    """The class of :func:`concentration_edges` that a step's mean reading falls in."""
    edges = concentration_edges(threshold_g_m3, class_factor, n_classes)
    return int(np.searchsorted(edges, mean_g_m3, side="right"))


def gamma_survival(edges_g_m3: FloatArray, mean_g_m3: FloatArray, shape: int) -> FloatArray:
    """P(c ≥ e) for c gamma-distributed with mean ``mean_g_m3`` and integer ``shape`` k, at each
    edge e: Q(k, x) = e^(−x)·Σ_{i<k} x^i/i!, x = k·e/mean (exponential for k = 1); shape
    ``(len(edges), *mean.shape)``. A mean of 0 never reaches a positive edge."""
    mean = np.maximum(np.asarray(mean_g_m3, dtype=float), 1e-300)  # 0: x large, S = 0
    x = (shape * edges_g_m3).reshape(-1, *([1] * mean.ndim)) / mean
    term = np.exp(-x)
    total = term.copy()
    for i in range(1, shape):
        term = term * x / i
        total += term
    return np.asarray(total)


def concentration_likelihoods(
    mean_g_m3: FloatArray,
    intermittency: float,
    shape: int,
    edges_g_m3: FloatArray,
    stray_probability: float,
) -> FloatArray:
    """``L[j, i] = P(a step's mean reading is in class j | mean concentration mean_g_m3[i])``.

    The reading is, with probability ``stray_probability``, a stray one that the plume model
    does not explain (exponential with mean the threshold, ``edges_g_m3[0]``: a filament or a
    noisy sample where the mean plume has none); otherwise zero with probability 1 − γ
    (``intermittency`` γ: the plume's blanks, a step the gas does not touch) and, with
    probability γ, gamma-distributed with mean c̄/γ and shape ``shape`` (so that its mean is
    the mean plume's c̄: k = 1 an exponential, the fluctuations of an intermittent plume;
    larger k a reading nearer its mean). With S(e) the probability of reaching edge e:
    L[0] = 1 − S(e₀), L[j] = S(e_(j−1)) − S(e_j), the last class S(e_last)."""
    mean = np.asarray(mean_g_m3, dtype=float)
    plume = intermittency * gamma_survival(edges_g_m3, mean / intermittency, shape)
    stray = np.exp(-edges_g_m3 / edges_g_m3[0]).reshape(-1, *([1] * mean.ndim))
    survival = (1.0 - stray_probability) * plume + stray_probability * stray
    out = np.empty((len(edges_g_m3) + 1, *mean.shape))
    out[0] = 1.0 - survival[0]
    out[1:-1] = survival[:-1] - survival[1:]
    out[-1] = survival[-1]
    return np.maximum(out, 0.0, out=out)  # a difference of two roundings may dip below 0


def unit_plume_g_m3(
    along_m: FloatArray,
    across_m: FloatArray,
    height_m: float,
    wind_speed_m_s: float,
    sigma_y_m: FloatArray,
    sigma_z_m: FloatArray,
) -> FloatArray:
    """The mean concentration (g/m³) of a Gaussian plume releasing 1 g/s at ``height_m`` (the
    searcher's own height: it flies the plume's centreline) at points ``along`` > 0 downwind
    and ``across`` of it, the ground reflecting: 1/(2π u σy σz) · exp(−y²/2σy²) · (1 +
    exp(−2H²/σz²))."""
    vertical = 1.0 + np.exp(-2.0 * height_m * height_m / (sigma_z_m * sigma_z_m))
    crosswind = np.exp(-0.5 * (across_m / sigma_y_m) ** 2)
    return np.asarray(
        crosswind * vertical / (2.0 * math.pi * wind_speed_m_s * sigma_y_m * sigma_z_m)
    )


def expected_entropy_shared(
    belief: FloatArray,
    likelihoods: SparseLikelihoods,
    here: BoolArray | IntArray | None,
) -> float:
    """``expected_entropy(belief, likelihoods.dense(), here, nuisance_axes=1)`` (to rounding)
    for likelihoods whose models all share one set of ``inside`` cells: the joint of each
    class and cell is the background's class times the cell's marginal belief outside them,
    and Σ_k L_k·b_k inside — one product over the models, whatever their number."""
    given, p_end = _ruled_out(belief, here)
    if p_end > 1.0 - EPSILON:
        return -EPSILON
    total = given.sum()
    if total > EPSILON:
        given /= total
    inside = likelihoods.inside[0]
    n_hits, models = len(likelihoods.background), belief.shape[0]
    joint = np.multiply.outer(likelihoods.background, given.sum(axis=0))
    classes = likelihoods.classes.reshape(n_hits, models, inside.size)
    joint[:, inside] = np.einsum("hmi,mi->hi", classes, given[:, inside])
    p_h = joint.sum(axis=1)
    return (1.0 - p_end) * float((p_h * _row_entropies_bits(joint, p_h)).sum())
