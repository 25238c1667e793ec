"""Filament plume of one source (Farrell et al. 2002, Environ. Fluid Mech. 2:143; pompy and
GADEN implement the same model).

The source releases filaments as a Poisson process of rate n (``release_rate_hz``), each
carrying the mass M = Q/n. A filament's centre moves with the wind plus centreline diffusion,

    dp = U(p, t) dt + √(2K) dW            (K: ``centerline_diffusivity_m2_s``)

integrated in internal steps of ``step_s`` as p += U·h + √(2K·h)·N(0, 1) — the Euler–Maruyama
form of the SDE, so the spread √(2K·age) does not depend on h — and reflected at the ground
(z → |z|). Its radius grows as R² = R0² + γ·age. The concentration is each filament's
normalised 3-D Gaussian plus its ground image,

    C(x) = Σ M·(2π)^−3/2·R^−3·[exp(−|x − p|²/2R²) + exp(−|x − p̄|²/2R²)] / P₄

truncated at 4R, where P₄ = P(|N₃| < 4) = erf(2√2) − 8·e^−8/√(2π) ≈ 0.99888 renormalises the
truncated kernel so each filament (with its image, over the half-space) carries exactly M.
Filaments older than ``max_age_s`` are dropped. The cut-off is ``truncate_radii`` R (default 4)
with the matching renormaliser. With a calibration (:mod:`plume_atmosphere.calibration`) the
centre's
step from age a to a + h has per-axis variance S(a + h) − S(a), the calibrated relative
variances S_y (x, y) and S_z (z), instead of 2K·h. Without meander the long-time average is the
Gaussian plume ``Q/(2πu s²)·exp(−y²/2s²)·[exp(−(z−H)²/2s²) + exp(−(z+H)²/2s²)]`` with
``s² = R0² + (2K + γ)·x/u``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from plume_atmosphere.calibration import AtmosphereCalibration
from plume_atmosphere.wind import WindModel
from plume_service.field import FloatArray
from plume_service.timestepped import TimeSteppedField
from swarmbus.scenario import PlumeFilament

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

#: Filaments are cut off at this many radii by default (``truncate_radii``).
TRUNCATE_RADII = 4.0
#: Up to this many points are evaluated against every filament directly; more go through a
#: k-d tree of the filaments (building it costs about as much as 16 direct points).
BRUTE_FORCE_POINTS = 16
#: Probability mass of a 3-D standard normal inside radius 4 (the truncation's renormaliser).


def inside_radii(radii: float) -> float:
    """P(|N₃| < r): the probability mass of a 3-D standard normal inside radius r."""
    return math.erf(radii / math.sqrt(2.0)) - (
        math.sqrt(2.0 / math.pi) * radii * math.exp(-(radii**2) / 2.0)
    )


INSIDE_4R = inside_radii(TRUNCATE_RADII)

#: Per filament: amplitude, 1/(2R²), squared cut-off radius (:func:`filament_kernel`).
Kernel = tuple[FloatArray, FloatArray, FloatArray]


@dataclass(frozen=True, slots=True)
class Filaments:
    """Live filaments: centres (F, 3) ENU m and the internal step each was released at."""

    positions: FloatArray
    birth_step: np.ndarray[Any, np.dtype[np.int64]]


def filament_kernel(
    radii: FloatArray, masses: FloatArray, truncate_radii: float = TRUNCATE_RADII
) -> Kernel:
    """Per filament: the amplitude M·(2π)^−3/2·R^−3/P, 1/(2R²) and the squared cut-off
    (``truncate_radii``·R)² of :func:`filament_concentration`."""
    norm = 1.0 / ((2.0 * math.pi) ** 1.5 * inside_radii(truncate_radii))
    amplitude = masses * norm / radii**3
    inv_two_r2 = 0.5 / radii**2
    cut2 = (truncate_radii * radii) ** 2
    return amplitude, inv_two_r2, cut2


def filament_concentration(
    points: FloatArray,
    centres: FloatArray,
    radii: FloatArray,
    masses: FloatArray,
    tree: cKDTree | None = None,
    truncate_radii: float = TRUNCATE_RADII,
    kernel: Kernel | None = None,
) -> FloatArray:
    """Σ over filaments of the Gaussian cut at ``truncate_radii`` R and renormalised, plus its
    ground image (g/m³) at (n, 3) points; exactly 0 below ground. ``tree``: a k-d tree of
    ``centres`` to reuse; ``kernel``: :func:`filament_kernel` of the filaments, if known."""
    out = np.zeros(points.shape[0])
    if centres.shape[0] == 0 or points.shape[0] == 0:
        return out
    reach = truncate_radii * float(radii.max())
    if kernel is None:
        kernel = filament_kernel(radii, masses, truncate_radii)
    amplitude, inv_two_r2, cut2 = kernel
    above = points[:, 2] >= 0.0
    if points.shape[0] <= BRUTE_FORCE_POINTS:
        for j in range(points.shape[0]):
            out[j] = _one_point(points[j], centres, reach, (amplitude, inv_two_r2, cut2))
        out[~above] = 0.0
        return out
    from scipy.spatial import cKDTree  # ≈ 30 MB: loaded by the filament model only

    if tree is None:
        tree = cKDTree(centres)
    for flip in (1.0, -1.0):
        mirrored = points * np.array([1.0, 1.0, flip])
        near = tree.sparse_distance_matrix(cKDTree(mirrored), reach, output_type="ndarray")
        if near.shape[0] == 0:
            continue
        fil, pt, dist = near["i"], near["j"], near["v"]
        d2 = dist * dist
        keep = d2 < cut2[fil]
        fil, pt, d2 = fil[keep], pt[keep], d2[keep]
        np.add.at(out, pt, amplitude[fil] * np.exp(-d2 * inv_two_r2[fil]))
    out[~above] = 0.0
    return out


def _one_point(point: FloatArray, centres: FloatArray, reach: float, kernel: Kernel) -> float:
    """:func:`filament_concentration` at one point, every filament measured directly."""
    amplitude, inv_two_r2, cut2 = kernel
    x, y, z = point
    dxy2 = (centres[:, 0] - x) ** 2 + (centres[:, 1] - y) ** 2
    # d2 = dxy2 + (cz − z)² is never below dxy2, so only the filaments whose cut-off reaches
    # across are measured in height (the same d2, bit for bit)
    near = np.flatnonzero(dxy2 < cut2)
    value = 0.0
    if not near.size:
        return value
    near_xy2, near_z, near_cut2 = dxy2[near], centres[near, 2], cut2[near]
    # the filament, then its ground image (mirror the point): centres are at z ≥ 0, so the
    # mirrored point is at least z from all of them and out of reach when z ≥ reach
    for zz in (z, -z) if z < reach else (z,):
        d2 = near_xy2 + (near_z - zz) ** 2
        inside = np.flatnonzero(d2 < near_cut2)
        if inside.size:
            hit = near[inside]
            value += float(np.dot(amplitude[hit], np.exp(-d2[inside] * inv_two_r2[hit])))
    return value


class FilamentPlume(TimeSteppedField[Filaments]):
    """One source's filaments in the scenario's wind; see the module docstring."""

    def __init__(
        self,
        source_m: tuple[float, float, float],
        release_rate_g_s: float,
        params: PlumeFilament,
        wind: WindModel,
        seed: int,
        stream: int = 0,
        calibration: AtmosphereCalibration | None = None,
    ) -> None:
        self.params = params
        self.calibration = calibration
        self.mass_g = release_rate_g_s / params.release_rate_hz
        self._max_age_steps = math.floor(params.max_age_s / params.step_s + 1e-9)
        self._noise = self._noise_by_age(params, calibration)
        self._tree: tuple[Filaments, cKDTree, FloatArray] | None = None
        # radii and kernels by age in internal steps: a filament's depend on its age alone
        self._radii_by_age: FloatArray = np.empty(0)
        self._kernel_by_age: Kernel = (np.empty(0), np.empty(0), np.empty(0))
        super().__init__(source_m, release_rate_g_s, wind, params.step_s, seed, stream)

    def _noise_by_age(
        self, params: PlumeFilament, calibration: AtmosphereCalibration | None
    ) -> FloatArray:
        """(ages, 3): the std of a filament centre's step from age step j to j + 1, per axis
        (x, y, z); √(2K·h) everywhere without a calibration, else the increments of the
        calibrated relative variances S_y (x and y) and S_z (z)."""
        ages = self._max_age_steps + 2
        h = params.step_s
        if calibration is None:
            std = math.sqrt(2.0 * params.centerline_diffusivity_m2_s * h)
            return np.full((ages, 3), std)
        age_s = np.arange(ages + 1, dtype=np.float64) * h
        radius2: FloatArray = params.initial_radius_m**2 + params.growth_m2_s * age_s
        s_y, s_z = calibration.relative_variances(age_s, radius2)
        table = np.empty((ages, 3))
        table[:, 0] = table[:, 1] = np.sqrt(np.diff(s_y))
        table[:, 2] = np.sqrt(np.diff(s_z))
        return table

    def initial_state(self) -> Filaments:
        return Filaments(np.empty((0, 3)), np.empty(0, dtype=np.int64))

    def copy_state(self, state: Filaments) -> Filaments:
        return Filaments(state.positions.copy(), state.birth_step.copy())

    def advance(self, state: Filaments, k: int, rng: np.random.Generator) -> Filaments:
        h = self.step_s
        p = state.positions
        born = state.birth_step
        uniform = self.wind.uniform_at(k * h)  # the same wind everywhere: no per-filament lookup
        # every centre draws its step (the dying ones too: the stream of draws stays the same)
        normal = rng.standard_normal(p.shape)
        # births only grow along the array, so the filaments that die are a prefix of it
        first = int(np.searchsorted(born, k + 1 - self._max_age_steps, side="left"))
        live = p.shape[0] - first
        new = int(rng.poisson(self.params.release_rate_hz * h))
        positions = np.empty((live + new, 3))
        moved = positions[:live]
        if uniform is None:
            np.add(p[first:], self.wind.velocity(p, k * h)[first:] * h, out=moved)
        else:
            step = np.asarray(uniform) * h
            for axis in range(3):  # a column at a time: numpy broadcasts a 3-vector slowly
                np.add(p[first:, axis], step[axis], out=moved[:, axis])
        ages = k - born[first:]
        np.minimum(ages, self._noise.shape[0] - 1, out=ages)
        moved += self._noise.take(ages, axis=0) * normal[first:]
        np.abs(moved[:, 2], out=moved[:, 2])
        positions[live:] = self.source_m
        births = np.empty(live + new, dtype=np.int64)
        births[:live] = born[first:]
        births[live:] = k + 1
        return Filaments(positions, births)

    def filaments(self, t: float) -> tuple[FloatArray, FloatArray]:
        """Centres (F, 3) and radii (F,) of the live filaments at sim time t."""
        k, state = self.state_at(t)
        return state.positions, self.radii(state, k)

    def radii(self, state: Filaments, k: int) -> FloatArray:
        return self._radii_of_ages(k - state.birth_step)

    def _radii_of_ages(self, steps: np.ndarray[Any, np.dtype[np.int64]]) -> FloatArray:
        age = steps * self.step_s
        p = self.params
        radii: FloatArray = np.sqrt(p.initial_radius_m**2 + p.growth_m2_s * age)
        return radii

    def _kernel_at(self, state: Filaments, k: int) -> tuple[FloatArray, Kernel]:
        """The live filaments' radii and :func:`filament_kernel`, looked up by age in tables
        computed once (the same operations on the same values as computing them per
        filament)."""
        ages = k - state.birth_step
        if ages.size and int(ages.max()) >= self._radii_by_age.shape[0]:
            table = np.arange(max(int(ages.max()) + 1, self._max_age_steps + 2), dtype=np.int64)
            radii = self._radii_of_ages(table)
            masses = np.full(table.shape[0], self.mass_g)
            self._radii_by_age = radii
            self._kernel_by_age = filament_kernel(radii, masses, self.params.truncate_radii)
        amplitude, inv_two_r2, cut2 = self._kernel_by_age
        return self._radii_by_age[ages], (amplitude[ages], inv_two_r2[ages], cut2[ages])

    def _evaluate(self, points: FloatArray, t: float | None, out: FloatArray) -> None:
        k, state = self.state_at(0.0 if t is None else t)
        cut = self.params.truncate_radii
        if points.shape[0] <= BRUTE_FORCE_POINTS:
            radii, kernel = self._kernel_at(state, k)
            out[:] = filament_concentration(
                points, state.positions, radii, radii, None, cut, kernel
            )
            return
        masses = np.full(state.birth_step.shape[0], self.mass_g)
        from scipy.spatial import cKDTree  # ≈ 30 MB: loaded by the filament model only

        with self._lock:
            if self._tree is None or self._tree[0] is not state:
                # one k-d tree per state, shared by every query of the same step
                self._tree = (state, cKDTree(state.positions), self.radii(state, k))
            _, tree, radii = self._tree
        out[:] = filament_concentration(points, state.positions, radii, masses, tree, cut)

    def info(self) -> dict[str, Any]:
        p = self.params
        return {
            "model": "filament",
            "release_rate_g_s": self.release_rate_g_s,
            "release_height_m": self.source_m[2],
            "source_m": [self.source_m[0], self.source_m[1]],
            "release_rate_hz": p.release_rate_hz,
            "filament_mass_g": self.mass_g,
            "initial_radius_m": p.initial_radius_m,
            "growth_m2_s": p.growth_m2_s,
            "centerline_diffusivity_m2_s": p.centerline_diffusivity_m2_s,
            "max_age_s": p.max_age_s,
            "truncate_radii": p.truncate_radii,
            "calibration": None if self.calibration is None else self.calibration.describe(),
            "wind": self.wind.info(),
            **self.time_info(),
        }
