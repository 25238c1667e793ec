"""State estimate from the physics' ground truth, with optional seeded noise (off by default).

The autopilot flies on this estimate, not on the truth: with noise on, hold and tracking errors
show what a real GNSS/INS would do to a swarm algorithm; with noise off, runs are exact.
"""

from __future__ import annotations

import numpy as np

from agents.control import Estimate
from swarmbus.messages import VehicleState


class Estimator:
    def __init__(
        self,
        position_noise_m: float = 0.0,
        velocity_noise_m_s: float = 0.0,
        seed: np.random.SeedSequence | None = None,
    ) -> None:
        self.position_noise_m = position_noise_m
        self.velocity_noise_m_s = velocity_noise_m_s
        self._rng = np.random.Generator(np.random.PCG64(seed))

    def estimate(self, state: VehicleState) -> Estimate:
        p = state.position_enu_m
        v = state.velocity_enu_m_s
        if self.position_noise_m > 0.0:
            n = self._rng.normal(0.0, self.position_noise_m, 3).tolist()
            p = (p[0] + n[0], p[1] + n[1], p[2] + n[2])
        if self.velocity_noise_m_s > 0.0:
            n = self._rng.normal(0.0, self.velocity_noise_m_s, 3).tolist()
            v = (v[0] + n[0], v[1] + n[1], v[2] + n[2])
        return Estimate(p, v, state.attitude_xyzw, state.body_rates_rad_s, state.on_ground)
