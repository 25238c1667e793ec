"""Puff plume of one source, CALPUFF-style (Scire et al. 2000, *A User's Guide for the CALPUFF
Dispersion Model*, v5, Earth Tech).

Every ``release_period_s`` Δt the source emits a puff of mass Q·Δt at (x_s, y_s, H). Its centre
moves with the scenario's wind at the release height (internal steps of ``step_s``; a puff
released inside a step is advected for the rest of it), and it remembers its travel distance s
(the path length). Its concentration is

    C = Q·Δt / ((2π)^{3/2} σy² σz) · exp(−r²/2σy²) · g(z)

with r the horizontal distance to the centre, σy = σx, σy(s) and σz(s) the plume's dispersion
curves (the same family, stability class and near-field guard as the Gaussian plume) at the
puff's travel, and g the Gaussian plume's vertical term: the ground image, and with a mixing
height L the images ±H + 2kL. Puffs older than ``max_age_s`` are dropped. In a steady wind the
puffs (spaced u·Δt apart) sum to the Gaussian plume Q/(2π u σy σz)·exp(−y²/2σy²)·g/… once they
have passed the point (tested to 1 %). The model has no random part: the seed is unused.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from plume_atmosphere.calibration import AtmosphereCalibration
from plume_atmosphere.dispersion import DispersionCurves, dispersion_curves
from plume_atmosphere.wind import WindModel
from plume_service.field import FloatArray
from plume_service.timestepped import TimeSteppedField
from swarmbus.scenario import PlumePuff

_TWO_PI_1_5 = (2.0 * math.pi) ** 1.5
#: Images farther than this many σz from the domain contribute < exp(−40) relative.
_IMAGE_SIGMAS = 9.0


@dataclass(frozen=True, slots=True)
class Puffs:
    """Live puffs: horizontal centres (P, 2) ENU m, travel (P,) m, release index (P,)."""

    centres: FloatArray
    travel_m: FloatArray
    index: np.ndarray[Any, np.dtype[np.int64]]


class PuffPlume(TimeSteppedField[Puffs]):
    """One source's puffs in the scenario's wind; see the module docstring."""

    def __init__(
        self,
        source_m: tuple[float, float, float],
        release_rate_g_s: float,
        params: PlumePuff,
        wind: WindModel,
        stability: str = "D",
        coefficients: str = "mcmullen",
        mixing_height: float | None = None,
        seed: int = 0,
        stream: int = 0,
        calibration: AtmosphereCalibration | None = None,
    ) -> None:
        self.params = params
        self.dispersion: DispersionCurves = dispersion_curves(coefficients, stability)
        self.calibration = calibration
        self.mixing_height_m = mixing_height
        if mixing_height is not None and mixing_height <= source_m[2]:
            raise ValueError(
                f"mixing_height must be above release_height={source_m[2]}, got {mixing_height!r}"
            )
        self.mass_g = release_rate_g_s * params.release_period_s
        super().__init__(source_m, release_rate_g_s, wind, params.step_s, seed, stream)

    def initial_state(self) -> Puffs:
        return Puffs(np.empty((0, 2)), np.empty(0), np.empty(0, dtype=np.int64))

    def copy_state(self, state: Puffs) -> Puffs:
        return Puffs(state.centres.copy(), state.travel_m.copy(), state.index.copy())

    def _move(self, centres: FloatArray, t: float, dt: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Centres after dt (per puff) in the wind at the release height at time t."""
        if centres.shape[0] == 0:
            return centres, np.empty(0)
        height = np.full((centres.shape[0], 1), self.source_m[2])
        u = self.wind.velocity(np.hstack([centres, height]), t)[:, :2]
        return centres + u * dt[:, None], np.hypot(u[:, 0], u[:, 1]) * dt

    def advance(self, state: Puffs, k: int, rng: np.random.Generator) -> Puffs:
        h, period = self.step_s, self.params.release_period_s
        t0, t1 = k * h, (k + 1) * h
        moved, travelled = self._move(state.centres, t0, np.full(state.index.shape[0], h))
        # releases j·Δt in [t0, t1): each advected for the rest of the step
        first = math.ceil(t0 / period - 1e-9)
        last = math.ceil(t1 / period - 1e-9)  # exclusive
        new_index = np.arange(first, last, dtype=np.int64)
        rest = (t1 - new_index * period).astype(np.float64)
        fresh = np.tile(self.source_m[:2], (new_index.shape[0], 1))
        fresh, fresh_travel = self._move(fresh, t0, rest)
        index = np.concatenate([state.index, new_index])
        alive = t1 - index * period <= self.params.max_age_s + 1e-9
        return Puffs(
            np.concatenate([moved, fresh])[alive],
            np.concatenate([state.travel_m + travelled, fresh_travel])[alive],
            index[alive],
        )

    def puffs(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Centres (P, 3), σy (P,) and σz (P,) of the live puffs at sim time t."""
        _, state = self.state_at(t)
        travel = np.maximum(state.travel_m, 1e-9)
        sigma_y, sigma_z = self.dispersion.sigmas(travel)
        if self.calibration is not None:
            # the meander (and the local turbulence) carry the puffs: their own σy is the rest
            meander = self.calibration.carried_variance(travel / self.calibration.wind_speed_m_s)
            sigma_y = np.sqrt(np.maximum(sigma_y**2 - meander, 1e-4 * sigma_y**2))
        height = np.full((state.centres.shape[0], 1), self.source_m[2])
        return np.hstack([state.centres, height]), sigma_y, sigma_z

    def _evaluate(self, points: FloatArray, t: float | None, out: FloatArray) -> None:
        centres, sigma_y, sigma_z = self.puffs(0.0 if t is None else t)
        out.fill(0.0)
        if centres.shape[0] == 0:
            return
        lid = self.mixing_height_m
        inside = points[:, 2] >= 0.0
        if lid is not None:
            inside &= points[:, 2] <= lid
        amplitude = self.mass_g / (_TWO_PI_1_5 * sigma_y**2 * sigma_z)
        inv_y = 0.5 / sigma_y**2
        inv_z = 0.5 / sigma_z**2
        heights = self._image_heights(float(sigma_z.max()))
        # points in blocks so the (points × puffs) temporaries stay small
        block = max(1, 200_000 // centres.shape[0])
        for start in range(0, points.shape[0], block):
            p = points[start : start + block]
            r2 = (p[:, None, 0] - centres[None, :, 0]) ** 2 + (
                p[:, None, 1] - centres[None, :, 1]
            ) ** 2
            # only the (point, puff) pairs within _IMAGE_SIGMAS σy of each other contribute
            arg = r2 * inv_y
            pt, puff = np.nonzero(arg < 0.5 * _IMAGE_SIGMAS**2)
            z = p[pt, 2]
            vertical = np.zeros(pt.shape[0])
            for image in heights:
                vertical += np.exp(-((z - image) ** 2) * inv_z[puff])
            terms = amplitude[puff] * np.exp(-arg[pt, puff]) * vertical
            out[start : start + block] = np.bincount(pt, weights=terms, minlength=p.shape[0])
        out[~inside] = 0.0

    def _image_heights(self, sigma_z_max: float) -> list[float]:
        height = self.source_m[2]
        lid = self.mixing_height_m
        if lid is None:
            return [height, -height]
        images = math.ceil((_IMAGE_SIGMAS * sigma_z_max + 2.0 * lid) / (2.0 * lid))
        return [s + 2.0 * k * lid for k in range(-images, images + 1) for s in (height, -height)]

    def info(self) -> dict[str, Any]:
        return {
            "model": "puff",
            "release_rate_g_s": self.release_rate_g_s,
            "release_height_m": self.source_m[2],
            "source_m": [self.source_m[0], self.source_m[1]],
            "release_period_s": self.params.release_period_s,
            "puff_mass_g": self.mass_g,
            "max_age_s": self.params.max_age_s,
            "stability": self.dispersion.stability,
            "coefficients": self.dispersion.family,
            "mixing_height_m": self.mixing_height_m,
            "dispersion": self.dispersion.describe(),
            "calibration": None if self.calibration is None else self.calibration.describe(),
            "wind": self.wind.info(),
            **self.time_info(),
        }
