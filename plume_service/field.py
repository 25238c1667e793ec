"""The concentration-field interface every plume model implements, and superposition of fields.

A field is a vectorised callable ``concentration(points[N, 3], t) -> values[N]`` in world ENU
metres (x east, y north, z up) and g/m³, so the same call serves one sensor, a batch query
over the bus and a mesh grid. :class:`ConcentrationField` validates the points once and
evaluates them in chunks of :data:`CHUNK_POINTS` so memory stays bounded however large the
input; a model only implements :meth:`ConcentrationField._evaluate` on one valid chunk.
Time-dependent models (puffs, filaments) plug in behind the same interface and use ``t``.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import numpy as np
import numpy.typing as npt

logger = logging.getLogger(__name__)

FloatArray = npt.NDArray[np.float64]

#: Points evaluated per chunk. Small enough that a chunk's temporaries stay in cache, large
#: enough that Python overhead per chunk is negligible; bounds memory for huge grids.
CHUNK_POINTS = 1 << 16

#: Inputs at least this large are split across two threads (numpy releases the GIL).
THREADED_MIN_POINTS = 1 << 19
_THREADS = 2


def as_points(points: npt.ArrayLike) -> FloatArray:
    """Return ``points`` as a C-contiguous (N, 3) float64 array, or raise ValueError.

    Finiteness is checked chunk by chunk by :func:`check_finite`, keeping temporaries small.
    """
    try:
        array = np.ascontiguousarray(points, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"points must be an (N, 3) array of numbers: {exc}") from exc
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got shape {array.shape}")
    return array


def check_finite(points: FloatArray, first_row: int = 0) -> None:
    """Raise ValueError naming the first row of ``points`` that is not finite."""
    finite = np.isfinite(points)
    if not finite.all():
        bad = int(np.flatnonzero(~finite.all(axis=1))[0])
        raise ValueError(f"points must be finite; row {first_row + bad} is {points[bad].tolist()}")


def check_time(t: float | None) -> float | None:
    """Reject a non-finite simulation time; None means "steady state / now"."""
    if t is not None and not np.isfinite(t):
        raise ValueError(f"t must be finite or None, got {t!r}")
    return t


class ConcentrationField(ABC):
    """A scalar concentration field C(points, t) in g/m³."""

    def concentration(self, points: npt.ArrayLike, t: float | None = None) -> FloatArray:
        """Concentration (g/m³) at each of N world ENU points (metres), shape (N,), float64.

        ``t`` is the simulation time in seconds; steady-state models ignore it.
        Raises ValueError for points that are not (N, 3) finite numbers.
        """
        array = as_points(points)
        t = check_time(t)
        n = array.shape[0]
        out = np.empty(n, dtype=np.float64)
        starts = range(0, n, CHUNK_POINTS)
        # Validate every chunk before evaluating any, so a bad row raises before any work.
        for start in starts:
            check_finite(array[start : start + CHUNK_POINTS], start)

        def run(start: int) -> None:
            stop = min(start + CHUNK_POINTS, n)
            self._evaluate(array[start:stop], t, out[start:stop])

        if n >= THREADED_MIN_POINTS:
            with ThreadPoolExecutor(max_workers=_THREADS) as pool:
                for _ in pool.map(run, starts):
                    pass
        else:
            for start in starts:
                run(start)
        return out

    @abstractmethod
    def _evaluate(self, points: FloatArray, t: float | None, out: FloatArray) -> None:
        """Write the concentration at one chunk of validated (n, 3) points into ``out`` (n,)."""

    @abstractmethod
    def info(self) -> dict[str, Any]:
        """Plain JSON-serialisable description: model, parameters, sources, wind."""


class PlumeField(ConcentrationField):
    """Superposition of several fields (sources): C = Σ Cᵢ, as the dispersion equation is linear."""

    def __init__(self, sources: Sequence[ConcentrationField]) -> None:
        sources = list(sources)
        if not sources:
            raise ValueError("sources must contain at least one field, got an empty list")
        for index, source in enumerate(sources):
            if not isinstance(source, ConcentrationField):
                raise ValueError(
                    f"sources[{index}] must be a ConcentrationField, got {type(source).__name__}"
                )
        self.sources: tuple[ConcentrationField, ...] = tuple(sources)

    def _evaluate(self, points: FloatArray, t: float | None, out: FloatArray) -> None:
        self.sources[0]._evaluate(points, t, out)
        if len(self.sources) > 1:
            term = np.empty_like(out)
            for source in self.sources[1:]:
                source._evaluate(points, t, term)
                out += term

    def info(self) -> dict[str, Any]:
        return {"model": "superposition", "sources": [source.info() for source in self.sources]}
