"""The scenario's one wind: a vectorised, deterministic ``velocity(points[N, 3], t) -> (N, 3)``.

Every consumer (the physics' vehicle drag, the plume's advection, each vehicle's anemometer)
builds the same :class:`WindModel` from the scenario with :func:`wind_from_scenario` and gets
the same value at the same (position, sim time), whichever process asks and in whatever order:
the random parts are drawn in fixed blocks of internal steps from generators seeded by the
scenario seed and the block's index, and state is recomputed from the start or a kept checkpoint
when an earlier time is asked for (a physics restart).

Models (``[wind] model``):

``steady``
    The mean wind, ``speed_m_s`` from ``from_deg`` (meteorological), everywhere and always.
``meander``
    The mean wind plus Farrell et al. (2002, Environ. Fluid Mech. 2:143) coloured noise on each
    horizontal component, the 2nd-order process ``ẍ + 2ζω ẋ + ω² x = G ω² ξ(t)``. Written as the
    SDE ``dx = v dt``, ``dv = (−2ζω v − ω² x) dt + σ dW`` with ``σ = G ω² √T_F``, where ``T_F``
    = 0.01 s is the step of Farrell's discrete noise, so G keeps its published meaning; the
    stationary std of x is ``G √T_F √(ω/4ζ)`` (small: 0.47 m/s, large: 1.41 m/s). The SDE is
    integrated exactly over each internal step (Van Loan's matrix exponential), so its
    statistics do not depend on ``step_s``; between steps the value is interpolated linearly.
    The process starts in its stationary distribution at t = 0. ``process = "ou"`` uses an
    Ornstein–Uhlenbeck process instead (std ``std_m_s``, timescale ``timescale_s``, exact
    steps): the meander a calibrated plume derives (:mod:`plume_atmosphere.calibration`).
``field``
    A 2-D grid (``spacing_m``, over ``[−extent_m, extent_m]²``): the meander noise drives the
    four corners, the edges interpolate them linearly and the interior follows the linear
    advection–diffusion ``∂u/∂t = −U·∇u + K∇²u`` (upwind, explicit, stable substeps) with the
    mean wind U and ``diffusivity_m2_s`` K (Farrell et al. 2002, §3). Queries interpolate the
    grid bilinearly (clamped to its edges); the grid is held between internal steps.

Local turbulence (``[wind.turbulence]``, any model): a spatially correlated perturbation added
to the wind above, a kinematic simulation (Kraichnan 1970, "Diffusion by a random velocity
field", Phys. Fluids 13:22; Fung et al. 1992, J. Fluid Mech. 236:281) frozen in the frame that
moves with the mean wind U and decorrelating in it. Each component i (along the mean wind,
across it, up) is ``σi·√(2/M)·Σₙ cos(kₙ·(x − U t) + ωₙ t + φₙ)`` over M modes, with kₙ drawn
from the 3-D Cauchy distribution of scale 1/L, ωₙ from the Cauchy distribution of scale 1/T
and φₙ uniform, all from a generator seeded by the scenario seed: a closed-form function of
(x, t), the same for every process and order, whose ensemble covariance is
``σi²·exp(−|r − Uτ|/L)·exp(−|τ|/T)`` (integral length scale L, timescale T) and whose variance
over space is σi² in every realisation (:class:`TurbulenceField`).
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt


# What the wind models read of a scenario's ``[wind]`` section (``swarmbus.scenario_spec``): the
# shapes, so this layer imports nothing of the contract's.
class WindMeander(Protocol):
    @property
    def process(self) -> str: ...
    @property
    def gain(self) -> float: ...
    @property
    def damping(self) -> float: ...
    @property
    def bandwidth_rad_s(self) -> float: ...
    @property
    def std_m_s(self) -> float: ...
    @property
    def timescale_s(self) -> float: ...
    @property
    def step_s(self) -> float: ...
    def resolved(self) -> WindMeander: ...


class WindField(Protocol):
    @property
    def spacing_m(self) -> float: ...
    @property
    def extent_m(self) -> float: ...
    @property
    def diffusivity_m2_s(self) -> float: ...


class WindTurbulence(Protocol):
    @property
    def std_m_s(self) -> tuple[float, float, float]: ...
    @property
    def length_scale_m(self) -> float: ...
    @property
    def timescale_s(self) -> float: ...
    @property
    def modes(self) -> int: ...


class Wind(Protocol):
    @property
    def model(self) -> str: ...
    @property
    def speed_m_s(self) -> float: ...
    @property
    def from_deg(self) -> float: ...
    @property
    def meander(self) -> WindMeander: ...
    @property
    def field(self) -> WindField: ...
    @property
    def turbulence(self) -> WindTurbulence | None: ...


class _World(Protocol):
    @property
    def seed(self) -> int: ...


class Scenario(Protocol):
    @property
    def wind(self) -> Wind: ...
    @property
    def world(self) -> _World: ...


FloatArray = npt.NDArray[np.float64]

#: The step (s) of Farrell et al.'s discrete coloured noise, which sets the SDE form of G.
FARRELL_STEP_S = 0.01
#: Internal steps drawn and integrated per block (each block has its own seeded generator).
BLOCK_STEPS = 1024
_WIND_STREAM = 0x57494E44  # "WIND": separates the wind's random streams from everyone else's


def wind_vector_enu(speed_m_s: float, from_deg: float) -> tuple[float, float, float]:
    """The air's velocity in ENU for a meteorological wind (``from_deg`` 270 → toward +x)."""
    rad = math.radians(from_deg)
    return (-speed_m_s * math.sin(rad), -speed_m_s * math.cos(rad), 0.0)


def step_index(t: float, step_s: float) -> tuple[int, float]:
    """(k, fraction) with t = (k + fraction)·step_s; times just below a step count as on it."""
    scaled = max(t, 0.0) / step_s
    k = math.floor(scaled + 1e-9)
    return k, max(scaled - k, 0.0)


#: Checkpoints of stepped state kept at every block for the newest RECENT_CHECKPOINTS blocks, older
#: ones only every THIN_EVERY-th block: memory grows slowly over long runs while going back a
#: few seconds (a physics restart) stays cheap.
RECENT_CHECKPOINTS = 32
THIN_EVERY = 16


def thin_checkpoints(checkpoints: dict[int, Any], newest: int, block_steps: int) -> None:
    """Drop the checkpoints (keyed by step) that :data:`RECENT_CHECKPOINTS` and
    :data:`THIN_EVERY` do not keep; ``newest`` is the newest checkpoint's step."""
    recent = newest - RECENT_CHECKPOINTS * block_steps
    for k in [k for k in checkpoints if k < recent]:
        if (k // block_steps) % THIN_EVERY:
            del checkpoints[k]


class WindModel(ABC):
    """The wind, a vectorised callable of world ENU points (metres) and sim time (s)."""

    mean_enu_m_s: tuple[float, float, float]

    @abstractmethod
    def velocity(self, points: npt.ArrayLike, t: float) -> FloatArray:
        """Air velocity (m/s, ENU) at each of N points at sim time ``t``: shape (N, 3)."""

    @property
    def steady(self) -> bool:
        return False

    def uniform_at(self, t: float) -> tuple[float, float, float] | None:
        """The wind at time t if it is the same everywhere (steady, meander), else None: lets
        a consumer skip looking up positions."""
        return None

    def info(self) -> dict[str, Any]:
        return {"model": type(self).__name__, "mean_enu_m_s": list(self.mean_enu_m_s)}


def _points(points: npt.ArrayLike) -> FloatArray:
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got shape {array.shape}")
    return array


class SteadyWind(WindModel):
    def __init__(self, speed_m_s: float, from_deg: float) -> None:
        self.mean_enu_m_s = wind_vector_enu(speed_m_s, from_deg)

    @property
    def steady(self) -> bool:
        return True

    def uniform_at(self, t: float) -> tuple[float, float, float]:
        return self.mean_enu_m_s

    def velocity(self, points: npt.ArrayLike, t: float) -> FloatArray:
        n = _points(points).shape[0]
        return np.tile(np.asarray(self.mean_enu_m_s, dtype=np.float64), (n, 1))


class ColouredNoise:
    """Independent copies of Farrell's 2nd-order process, exact on a grid of ``step_s``.

    ``values(k)`` is the (copies,) vector of x at internal step k; the history is kept, so any
    step is answered by lookup once reached, in any order.
    """

    def __init__(self, config: WindMeander, copies: int, seed: int, stream: int) -> None:
        cfg = config.resolved()
        self.step_s = cfg.step_s
        self.copies = copies
        self._seed = seed
        self._stream = stream
        self._blocks: list[FloatArray] = []
        self._state = np.zeros((2, copies))
        if cfg.process == "ou":
            self._ornstein_uhlenbeck(cfg.std_m_s, cfg.timescale_s)
            return
        omega, zeta = cfg.bandwidth_rad_s, cfg.damping
        self.sigma = cfg.gain * omega**2 * math.sqrt(FARRELL_STEP_S)
        a = np.array([[0.0, 1.0], [-(omega**2), -2.0 * zeta * omega]])
        bbt = np.array([[0.0, 0.0], [0.0, self.sigma**2]])
        # Van Loan: expm([[−A, BBᵀ], [0, Aᵀ]]·h) = [[·, F⁻¹Q], [0, Fᵀ]].
        van_loan = np.zeros((4, 4))
        van_loan[:2, :2] = -a
        van_loan[:2, 2:] = bbt
        van_loan[2:, 2:] = a.T
        # scipy.linalg costs ≈ 25 MB and ≈ 0.2 s per process: load it only where a meander is set.
        from scipy.linalg import expm

        c = expm(van_loan * self.step_s)
        self._f = c[2:, 2:].T
        q = self._f @ c[:2, 2:]
        q = 0.5 * (q + q.T)
        self._l = np.linalg.cholesky(q + 1e-300 * np.eye(2))
        #: Stationary std of x (m/s): σ/√(4ζω³) = G √T_F √(ω/4ζ).
        self.stationary_std = self.sigma / math.sqrt(4.0 * zeta * omega**3)
        self._stationary_v_std = self.sigma / math.sqrt(4.0 * zeta * omega)

    def _ornstein_uhlenbeck(self, std: float, timescale: float) -> None:
        """x_{k+1} = a·x_k + std·√(1 − a²)·N(0, 1), a = e^(−h/T_L): exact for any step; the
        second state is unused (kept at 0)."""
        a = math.exp(-self.step_s / timescale)
        self.sigma = std * math.sqrt(2.0 / timescale)
        self._f = np.array([[a, 0.0], [0.0, 0.0]])
        self._l = np.array(
            [[std * math.sqrt(-math.expm1(-2.0 * self.step_s / timescale)), 0.0], [0.0, 0.0]]
        )
        self.stationary_std = std
        self._stationary_v_std = 0.0

    def _rng(self, block: int) -> np.random.Generator:
        seq = np.random.SeedSequence([self._seed, _WIND_STREAM, self._stream, block])
        return np.random.Generator(np.random.PCG64(seq))

    def _extend(self) -> None:
        block = len(self._blocks)
        rng = self._rng(block)
        z = rng.standard_normal((BLOCK_STEPS, 2, self.copies))
        out = np.empty((BLOCK_STEPS, self.copies))
        state = self._state
        start = 0
        if block == 0:
            state = np.stack([self.stationary_std * z[0, 0], self._stationary_v_std * z[0, 1]])
            out[0] = state[0]
            start = 1
        f, low = self._f, self._l
        for k in range(start, BLOCK_STEPS):
            state = f @ state + low @ z[k]
            out[k] = state[0]
        self._state = state
        self._blocks.append(out)

    def values(self, k: int) -> FloatArray:
        block = k // BLOCK_STEPS
        while block >= len(self._blocks):
            self._extend()
        row: FloatArray = self._blocks[block][k % BLOCK_STEPS]
        return row

    def at(self, t: float) -> FloatArray:
        """x at sim time t, linear between internal steps."""
        k, frac = step_index(t, self.step_s)
        x0 = self.values(k)
        if frac == 0.0:
            return x0.copy()
        return x0 + frac * (self.values(k + 1) - x0)


class MeanderWind(WindModel):
    """Mean wind plus coloured noise on east and north (uniform in space)."""

    def __init__(self, wind: Wind, seed: int) -> None:
        self.mean_enu_m_s = wind_vector_enu(wind.speed_m_s, wind.from_deg)
        self.config = wind.meander.resolved()
        self.noise = ColouredNoise(self.config, copies=2, seed=seed, stream=0)
        self._lock = threading.Lock()
        self._last: tuple[float, tuple[float, float, float]] | None = None

    def at(self, t: float) -> tuple[float, float, float]:
        """The wind (everywhere) at sim time t; the last answer is kept (one call per tick)."""
        last = self._last
        if last is not None and last[0] == t:
            return last[1]
        k, frac = step_index(t, self.noise.step_s)
        with self._lock:
            r0 = self.noise.values(k).tolist()
            r1 = self.noise.values(k + 1).tolist() if frac else r0
        mx, my, mz = self.mean_enu_m_s
        value = (mx + r0[0] + frac * (r1[0] - r0[0]), my + r0[1] + frac * (r1[1] - r0[1]), mz)
        self._last = (t, value)
        return value

    def uniform_at(self, t: float) -> tuple[float, float, float]:
        return self.at(t)

    def velocity(self, points: npt.ArrayLike, t: float) -> FloatArray:
        n = _points(points).shape[0]
        return np.tile(np.asarray(self.at(t), dtype=np.float64), (n, 1))

    def info(self) -> dict[str, Any]:
        return {
            "model": "meander",
            "mean_enu_m_s": list(self.mean_enu_m_s),
            "process": self.config.process,
            "timescale_s": self.config.timescale_s,
            "gain": self.config.gain,
            "damping": self.config.damping,
            "bandwidth_rad_s": self.config.bandwidth_rad_s,
            "step_s": self.config.step_s,
            "stationary_std_m_s": self.noise.stationary_std,
        }


#: Grid checkpoints kept every this many internal steps (going back in time restarts there).
FIELD_CHECKPOINT_STEPS = 64


class GridWind(WindModel):
    """Farrell's spatially varying wind on a 2-D grid (see the module docstring)."""

    def __init__(self, wind: Wind, seed: int) -> None:
        self.mean_enu_m_s = wind_vector_enu(wind.speed_m_s, wind.from_deg)
        self.meander = wind.meander.resolved()
        self.config: WindField = wind.field
        cfg = self.config
        cells = max(2, round(2.0 * cfg.extent_m / cfg.spacing_m))
        self.axis_m = np.linspace(-cfg.extent_m, cfg.extent_m, cells + 1)
        self.dx_m = float(self.axis_m[1] - self.axis_m[0])
        self.step_s = self.meander.step_s
        # corners: (x0,y0), (x1,y0), (x0,y1), (x1,y1), each with an east and a north copy
        self.corners = ColouredNoise(self.meander, copies=8, seed=seed, stream=1)
        ux, uy, _ = self.mean_enu_m_s
        speed = max(abs(ux), abs(uy), 1e-9)
        limit = 0.4 * self.dx_m / speed
        if cfg.diffusivity_m2_s > 0.0:
            limit = min(limit, 0.2 * self.dx_m**2 / cfg.diffusivity_m2_s)
        self.substeps = max(1, math.ceil(self.step_s / limit))
        self._checkpoints: dict[int, FloatArray] = {}
        self._k = 0
        self._grid = self._boundary_frame(0, np.zeros((2, cells + 1, cells + 1)), fill=True)
        self._checkpoints[0] = self._grid.copy()
        self._lock = threading.Lock()

    def _boundary_frame(self, k: int, grid: FloatArray, fill: bool = False) -> FloatArray:
        """Set the edges (and with ``fill`` the whole grid) from the corner noise at step k."""
        c = self.corners.values(k).reshape(4, 2)  # corner, component
        s = np.linspace(0.0, 1.0, grid.shape[1])
        for comp in range(2):
            c00, c10, c01, c11 = c[:, comp]
            # bilinear in (x index i, y index j)
            if fill:
                si, sj = np.meshgrid(s, s, indexing="ij")
                grid[comp] = (
                    c00 * (1 - si) * (1 - sj)
                    + c10 * si * (1 - sj)
                    + c01 * (1 - si) * sj
                    + c11 * si * sj
                )
            else:
                grid[comp, :, 0] = c00 * (1 - s) + c10 * s
                grid[comp, :, -1] = c01 * (1 - s) + c11 * s
                grid[comp, 0, :] = c00 * (1 - s) + c01 * s
                grid[comp, -1, :] = c10 * (1 - s) + c11 * s
        return grid

    def _advance(self) -> None:
        ux, uy, _ = self.mean_enu_m_s
        h = self.step_s / self.substeps
        dx = self.dx_m
        kappa = self.config.diffusivity_m2_s
        g = self._grid
        for _ in range(self.substeps):
            inner = g[:, 1:-1, 1:-1]
            # upwind first differences along x (axis 1) and y (axis 2)
            back_x = inner - g[:, :-2, 1:-1]
            ahead_x = g[:, 2:, 1:-1] - inner
            back_y = inner - g[:, 1:-1, :-2]
            ahead_y = g[:, 1:-1, 2:] - inner
            ddx = (back_x if ux >= 0 else ahead_x) / dx
            ddy = (back_y if uy >= 0 else ahead_y) / dx
            lap = (
                g[:, 2:, 1:-1] + g[:, :-2, 1:-1] + g[:, 1:-1, 2:] + g[:, 1:-1, :-2] - 4 * inner
            ) / dx**2
            g[:, 1:-1, 1:-1] = inner + h * (-ux * ddx - uy * ddy + kappa * lap)
        self._k += 1
        self._boundary_frame(self._k, g)
        if self._k % FIELD_CHECKPOINT_STEPS == 0:
            self._checkpoints[self._k] = g.copy()
            thin_checkpoints(self._checkpoints, self._k, FIELD_CHECKPOINT_STEPS)

    def grid_at_step(self, k: int) -> FloatArray:
        """The perturbation grid (2, nx, ny) at internal step k (a view; do not modify)."""
        if k < self._k:
            base = max(s for s in self._checkpoints if s <= k)
            self._grid = self._checkpoints[base].copy()
            self._k = base
        while self._k < k:
            self._advance()
        return self._grid

    def velocity(self, points: npt.ArrayLike, t: float) -> FloatArray:
        p = _points(points)
        k, _ = step_index(t, self.step_s)
        lo, n = float(self.axis_m[0]), self.axis_m.shape[0]
        fx = np.clip((p[:, 0] - lo) / self.dx_m, 0.0, n - 1.000001)
        fy = np.clip((p[:, 1] - lo) / self.dx_m, 0.0, n - 1.000001)
        i, j = fx.astype(np.int64), fy.astype(np.int64)
        ax, ay = fx - i, fy - j
        out = np.empty((p.shape[0], 3))
        with self._lock:
            g = self.grid_at_step(k)
            for comp in range(2):
                q = g[comp]
                out[:, comp] = (
                    q[i, j] * (1 - ax) * (1 - ay)
                    + q[i + 1, j] * ax * (1 - ay)
                    + q[i, j + 1] * (1 - ax) * ay
                    + q[i + 1, j + 1] * ax * ay
                ) + self.mean_enu_m_s[comp]
        out[:, 2] = self.mean_enu_m_s[2]
        return out

    def info(self) -> dict[str, Any]:
        return {
            "model": "field",
            "mean_enu_m_s": list(self.mean_enu_m_s),
            "spacing_m": self.dx_m,
            "extent_m": self.config.extent_m,
            "diffusivity_m2_s": self.config.diffusivity_m2_s,
            "gain": self.meander.gain,
            "damping": self.meander.damping,
            "bandwidth_rad_s": self.meander.bandwidth_rad_s,
            "step_s": self.step_s,
        }


class TurbulenceField:
    """The local turbulence's perturbation (see the module docstring): ``at(points, t)``."""

    def __init__(
        self, config: WindTurbulence, mean_enu_m_s: tuple[float, float, float], seed: int
    ) -> None:
        self.config = config
        modes = config.modes
        rng = np.random.Generator(
            np.random.PCG64(np.random.SeedSequence([seed, _WIND_STREAM, 2, 0]))
        )
        # a 3-D Cauchy vector of scale 1/L is a normal one over |N(0, 1)|: its characteristic
        # function, the field's spatial correlation, is exp(−|r|/L)
        normal = rng.standard_normal((3, modes, 3))
        chi = np.maximum(np.abs(rng.standard_normal((3, modes, 1))), 1e-12)
        self.wavenumbers: FloatArray = normal / (chi * config.length_scale_m)
        # ω: Cauchy of scale 1/T, so E[cos ωτ] = exp(−|τ|/T)
        ratio = rng.standard_normal((3, modes)) / np.maximum(
            np.abs(rng.standard_normal((3, modes))), 1e-12
        )
        self.frequencies: FloatArray = ratio / config.timescale_s
        self.phases: FloatArray = rng.uniform(0.0, 2.0 * math.pi, (3, modes))
        self.amplitudes: FloatArray = np.asarray(config.std_m_s, dtype=np.float64) * math.sqrt(
            2.0 / modes
        )
        self.mean_enu_m_s = mean_enu_m_s
        speed = math.hypot(mean_enu_m_s[0], mean_enu_m_s[1])
        if speed > 0.0:
            self.along = (mean_enu_m_s[0] / speed, mean_enu_m_s[1] / speed)
        else:
            self.along = (1.0, 0.0)

    def components(self, points: npt.ArrayLike, t: float) -> FloatArray:
        """(N, 3): the perturbation along the mean wind, across it (to its left) and up."""
        p = _points(points)
        k = self.wavenumbers
        ux, uy, uz = self.mean_enu_m_s
        x = (p[:, 0] - ux * t)[:, None, None]
        y = (p[:, 1] - uy * t)[:, None, None]
        z = (p[:, 2] - uz * t)[:, None, None]
        arg = (
            x * k[:, :, 0] + y * k[:, :, 1] + z * k[:, :, 2] + (self.frequencies * t + self.phases)
        )
        out: FloatArray = np.cos(arg).sum(axis=2) * self.amplitudes
        return out

    def at(self, points: npt.ArrayLike, t: float) -> FloatArray:
        """(N, 3) ENU m/s: the perturbation at each point at sim time t."""
        c = self.components(points, t)
        ax, ay = self.along
        out = np.empty_like(c)
        out[:, 0] = c[:, 0] * ax - c[:, 1] * ay
        out[:, 1] = c[:, 0] * ay + c[:, 1] * ax
        out[:, 2] = c[:, 2]
        return out

    def info(self) -> dict[str, Any]:
        cfg = self.config
        return {
            "std_m_s": list(cfg.std_m_s),
            "length_scale_m": cfg.length_scale_m,
            "timescale_s": cfg.timescale_s,
            "modes": cfg.modes,
        }


class TurbulentWind(WindModel):
    """A wind (``base``) plus the local turbulence: varies in space, so it is never uniform."""

    def __init__(self, base: WindModel, config: WindTurbulence, seed: int) -> None:
        self.base = base
        self.mean_enu_m_s = base.mean_enu_m_s
        self.turbulence = TurbulenceField(config, base.mean_enu_m_s, seed)

    def velocity(self, points: npt.ArrayLike, t: float) -> FloatArray:
        p = _points(points)
        out: FloatArray = self.base.velocity(p, t) + self.turbulence.at(p, t)
        return out

    def info(self) -> dict[str, Any]:
        return {**self.base.info(), "turbulence": self.turbulence.info()}


def wind_model(wind: Wind, seed: int) -> WindModel:
    """The wind a ``[wind]`` section describes, seeded by ``seed``."""
    base: WindModel
    if wind.model == "meander":
        base = MeanderWind(wind, seed)
    elif wind.model == "field":
        base = GridWind(wind, seed)
    else:
        base = SteadyWind(wind.speed_m_s, wind.from_deg)
    turbulence = wind.turbulence
    if turbulence is None:
        return base
    return TurbulentWind(base, turbulence, seed)


def wind_from_scenario(scenario: Scenario) -> WindModel:
    """The scenario's wind, seeded from ``world.seed``: the one every process uses."""
    return wind_model(scenario.wind, scenario.world.seed)
