"""The Gymnasium multi-vehicle task ``plumeswarm/PlumeSwarm-v0``: one policy flies every vehicle.

The PettingZoo environment (:class:`~plumeswarm.envs.swarm.PlumeSwarmEnv`) under one
Gymnasium ``Env``, for single-agent learners: the observation is the agents' observations
concatenated in the scenario's vehicle order, the action the agents' actions concatenated
(4 per vehicle), the reward their sum. The episode ends when a vehicle finds the source
(terminated), when every vehicle's own episode has ended (terminated if none ran out of time,
truncated otherwise). A vehicle whose episode ended holds where it is: its slice of the action is
ignored and its slice of the observation keeps its last value.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from plumeswarm.envs.swarm import Action, Obs, PlumeSwarmEnv
from plumeswarm.envs.wrapped import SwarmWrapper
from swarmbus.scenario import Scenario


class PlumeSwarmCentralEnv(SwarmWrapper):
    def __init__(
        self,
        scenario: Scenario | str | Path | None = None,
        *,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        """``kwargs``: the options of :class:`PlumeSwarmEnv` (``vehicles``, ``backend``,
        ``k_peers``, ...)."""
        swarm = PlumeSwarmEnv(scenario, render_mode=render_mode, **kwargs)
        super().__init__(swarm, render_mode)
        self.order = list(self.swarm.possible_agents)
        n, size = len(self.order), self.swarm.observation_size
        one = self.swarm.observation_space(self.order[0])
        self.observation_space = gymnasium.spaces.Box(
            float(one.low[0]), float(one.high[0]), shape=(n * size,), dtype=np.float32
        )
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(n * 4,), dtype=np.float32)
        self._last: dict[str, Obs] = {}
        self._truncated_any = False

    def _joined(self, observations: dict[str, Obs]) -> Obs:
        self._last.update(observations)
        return np.concatenate([self._last[a] for a in self.order]).astype(np.float32)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        observations, infos = self._reset_swarm(seed, options)
        self._last = {}
        self._truncated_any = False
        return self._joined(observations), {"agents": infos, "success": False}

    def step(self, action: Action) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        self._check_running()
        flat = np.asarray(action, dtype=np.float32).reshape(len(self.order), 4)
        actions = {a: flat[i] for i, a in enumerate(self.order) if a in self.swarm.agents}
        obs, rewards, _terminated, truncated, infos = self.swarm.step(actions)
        success = any(info["success"] for info in infos.values())
        self._truncated_any = self._truncated_any or any(truncated.values())
        everyone_done = not self.swarm.agents
        done_terminated = success or (everyone_done and not self._truncated_any)
        done_truncated = not done_terminated and everyone_done
        info = {
            "agents": infos,
            "success": success,
            "distance_m": min(i["distance_m"] for i in infos.values()),
        }
        return (
            self._joined(obs),
            float(sum(rewards.values())),
            done_terminated,
            done_truncated,
            info,
        )
