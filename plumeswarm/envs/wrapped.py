"""The base of the Gymnasium environments that fly one :class:`PlumeSwarmEnv` underneath."""

from __future__ import annotations

from typing import Any

import gymnasium

from plumeswarm.envs.swarm import RENDER_MODES, Action, Obs, PlumeSwarmEnv


class SwarmWrapper(gymnasium.Env[Obs, Action]):
    """A Gymnasium ``Env`` over ``swarm``: its seed decides the swarm's, it renders and closes
    the swarm; subclasses map the swarm's agents to their observation and action."""

    metadata = {"render_modes": RENDER_MODES, "render_fps": 10}  # noqa: RUF012 - Gymnasium's

    def __init__(self, swarm: PlumeSwarmEnv, render_mode: str | None) -> None:
        self.swarm = swarm
        self.render_mode = render_mode

    def _reset_swarm(
        self, seed: int | None, options: dict[str, Any] | None
    ) -> tuple[dict[str, Obs], dict[str, dict[str, Any]]]:
        super().reset(seed=seed)
        # The swarm env draws from its own generator, seeded from ours: one seed decides all.
        return self.swarm.reset(seed=int(self.np_random.integers(2**63 - 1)), options=options)

    def _check_running(self) -> None:
        if not self.swarm.agents:
            raise RuntimeError("step() after the episode ended: call reset()")

    def render(self) -> Any:
        return self.swarm.render()

    def close(self) -> None:
        self.swarm.close()
