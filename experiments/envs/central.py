"""The Gymnasium multi-vehicle task ``plumeswarm/PlumeSwarm-v0``: one policy flies every vehicle.

The PettingZoo environment (:class:`~experiments.envs.swarm.PlumeSwarmEnv`) under one
Gymnasium ``Env``, for single-agent learners: the observation is the agents' observations
concatenated in the scenario's vehicle order, the action the agents' actions concatenated
(4 per vehicle), the reward their sum. The episode ends when a vehicle finds the source
(terminated), when every vehicle's own episode has ended (terminated if none ran out of time,
truncated otherwise). A vehicle whose episode ended holds where it is: its slice of the action is
ignored and its slice of the observation keeps its last value.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np

from experiments.driver import Driver
from experiments.envs.swarm import RENDER_MODES, Action, Obs, PlumeSwarmEnv
from swarmbus.scenario import Scenario


class PlumeSwarmCentralEnv(gymnasium.Env[Obs, Action]):
    metadata = {"render_modes": RENDER_MODES, "render_fps": 10}  # noqa: RUF012 - Gymnasium's

    def __init__(
        self,
        scenario: Scenario | str | Path | None = None,
        *,
        scenario_overrides: Sequence[str] = (),
        vehicles: int | None = None,
        backend: str | Driver = "fused",
        k_peers: int = 2,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        self.swarm = PlumeSwarmEnv(
            scenario,
            scenario_overrides=scenario_overrides,
            vehicles=vehicles,
            backend=backend,
            k_peers=k_peers,
            render_mode=render_mode,
            **kwargs,
        )
        self.order = list(self.swarm.possible_agents)
        n, size = len(self.order), self.swarm.observation_size
        one = self.swarm.observation_space(self.order[0])
        self.observation_space = gymnasium.spaces.Box(
            float(one.low[0]), float(one.high[0]), shape=(n * size,), dtype=np.float32
        )
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, shape=(n * 4,), dtype=np.float32)
        self.render_mode = render_mode
        self._last: dict[str, Obs] = {}
        self._truncated_any = False

    def _joined(self, observations: dict[str, Obs]) -> Obs:
        self._last.update(observations)
        return np.concatenate([self._last[a] for a in self.order]).astype(np.float32)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        super().reset(seed=seed)
        observations, infos = self.swarm.reset(
            seed=int(self.np_random.integers(2**63 - 1)), options=options
        )
        self._last = {}
        self._truncated_any = False
        return self._joined(observations), {"agents": infos, "success": False}

    def step(self, action: Action) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        if not self.swarm.agents:
            raise RuntimeError("step() after the episode ended: call reset()")
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

    def render(self) -> Any:
        return self.swarm.render()

    def close(self) -> None:
        self.swarm.close()
