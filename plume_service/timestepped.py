"""A field whose state advances on the simulation clock in fixed internal steps.

The state at internal step k is a deterministic function of the model's parameters, its seed
and k: the random numbers of steps [b·B, (b+1)·B) come from one generator seeded with
(seed, stream, b), and a checkpoint of the state is kept at every block boundary, so asking for
an earlier time (a physics restart) restores the checkpoint at or before it and steps forward
again: the same bits as the first time. A query at sim time t sees the state of step
⌊t / step_s⌋ (held between steps).
"""

from __future__ import annotations

import threading
from abc import abstractmethod
from typing import Any, Generic, TypeVar

import numpy as np

from plume_atmosphere.wind import WindModel, step_index, thin_checkpoints
from plume_service.field import ConcentrationField

State = TypeVar("State")

#: Internal steps that share one seeded generator, and the spacing of kept checkpoints (thinned
#: by :func:`plume_atmosphere.wind.thin_checkpoints`).
BLOCK_STEPS = 64


class TimeSteppedField(ConcentrationField, Generic[State]):
    """Base of the filament and puff fields of one source (at ``source_m``, x, y and release
    height, releasing ``release_rate_g_s``) in ``wind``; subclasses say how one step changes
    the state."""

    def __init__(
        self,
        source_m: tuple[float, float, float],
        release_rate_g_s: float,
        wind: WindModel,
        step_s: float,
        seed: int,
        stream: int,
    ) -> None:
        self.source_m = source_m
        self.release_rate_g_s = release_rate_g_s
        self.wind = wind
        if not step_s > 0.0:
            raise ValueError(f"step_s must be > 0, got {step_s!r}")
        self.step_s = float(step_s)
        self._seed = seed
        self._stream = stream
        self._lock = threading.RLock()
        self._k = 0
        self._state = self.initial_state()
        self._checkpoints: dict[int, State] = {0: self.copy_state(self._state)}
        self._rng = self._block_rng(0)

    def _block_rng(self, block: int) -> np.random.Generator:
        seq = np.random.SeedSequence([self._seed, 0x504C554D, self._stream, block])
        return np.random.Generator(np.random.PCG64(seq))

    @abstractmethod
    def initial_state(self) -> State:
        """The state at step 0."""

    @abstractmethod
    def copy_state(self, state: State) -> State:
        """An independent copy (kept as a checkpoint)."""

    @abstractmethod
    def advance(self, state: State, k: int, rng: np.random.Generator) -> State:
        """The state of step k + 1 from that of step k (sim time k·step_s)."""

    def state_at(self, t: float) -> tuple[int, State]:
        """(k, state of step k) for sim time t; do not modify the returned state."""
        k, _ = step_index(t, self.step_s)
        with self._lock:
            if k < self._k:
                base = max(s for s in self._checkpoints if s <= k)
                self._state = self.copy_state(self._checkpoints[base])
                self._k = base
                self._rng = self._block_rng(base // BLOCK_STEPS)
            while self._k < k:
                self._state = self.advance(self._state, self._k, self._rng)
                self._k += 1
                if self._k % BLOCK_STEPS == 0:
                    self._rng = self._block_rng(self._k // BLOCK_STEPS)
                    if self._k not in self._checkpoints:
                        self._checkpoints[self._k] = self.copy_state(self._state)
                        thin_checkpoints(self._checkpoints, self._k, BLOCK_STEPS)
            return self._k, self._state

    def time_info(self) -> dict[str, Any]:
        return {"step_s": self.step_s, "time_dependent": True}
