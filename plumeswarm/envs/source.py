"""The Gymnasium single-agent environment ``plumeswarm/PlumeSource-v0``: one vehicle, one source.

The scenario's first vehicle alone, through :class:`~plumeswarm.envs.swarm.PlumeSwarmEnv`: the same
start, action, reward and termination; the observation is that agent's without peers.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgspec
import numpy as np

from plumeswarm.envs.swarm import Action, Obs, PlumeSwarmEnv, env_scenario
from plumeswarm.envs.wrapped import SwarmWrapper
from swarmbus.scenario import Scenario


class PlumeSourceEnv(SwarmWrapper):
    def __init__(
        self,
        scenario: Scenario | str | Path | None = None,
        *,
        scenario_overrides: Sequence[str] = (),
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        """``kwargs``: the options of :class:`PlumeSwarmEnv` (``backend``, ``ticks_per_step``,
        the speed limits, ``reward_fn``, ...) but ``vehicles`` and ``k_peers``."""
        base = env_scenario(scenario, scenario_overrides)
        one = msgspec.structs.replace(base, vehicles=base.vehicles[:1])
        super().__init__(
            PlumeSwarmEnv(one, k_peers=0, render_mode=render_mode, **kwargs), render_mode
        )
        self.agent = self.swarm.possible_agents[0]
        self.observation_space = self.swarm.observation_space(self.agent)  # type: ignore[assignment]
        self.action_space = self.swarm.action_space(self.agent)  # type: ignore[assignment]

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        observations, infos = self._reset_swarm(seed, options)
        return observations[self.agent], infos[self.agent]

    def step(self, action: Action) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        self._check_running()
        obs, rewards, terminated, truncated, infos = self.swarm.step(
            {self.agent: np.asarray(action)}
        )
        a = self.agent
        return obs[a], rewards[a], terminated[a], truncated[a], infos[a]
