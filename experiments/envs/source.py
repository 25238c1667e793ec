"""The Gymnasium single-agent environment ``plumeswarm/PlumeSource-v0``: one vehicle, one source.

The scenario's first vehicle alone, through :class:`~experiments.envs.swarm.PlumeSwarmEnv`: the same
start, action, reward and termination; the observation is that agent's without peers.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import gymnasium
import msgspec
import numpy as np

from experiments.driver import Driver
from experiments.envs.swarm import (
    RENDER_MODES,
    Action,
    Obs,
    PlumeSwarmEnv,
    RewardFn,
    TerminationFn,
    env_scenario,
)
from experiments.envs.swarm import default_reward as _default_reward
from experiments.envs.swarm import default_termination as _default_termination
from swarmbus.scenario import Scenario


class PlumeSourceEnv(gymnasium.Env[Obs, Action]):
    metadata = {"render_modes": RENDER_MODES, "render_fps": 10}  # noqa: RUF012 - Gymnasium's

    def __init__(
        self,
        scenario: Scenario | str | Path | None = None,
        *,
        scenario_overrides: Sequence[str] = (),
        backend: str | Driver = "fused",
        attach: str | None = None,
        ticks_per_step: int = 12,
        max_speed_xy_m_s: float = 5.0,
        max_speed_z_m_s: float = 2.0,
        max_yaw_rate_deg_s: float = 90.0,
        reward_fn: RewardFn = _default_reward,
        termination_fn: TerminationFn = _default_termination,
        render_mode: str | None = None,
    ) -> None:
        base = env_scenario(scenario, scenario_overrides)
        one = msgspec.structs.replace(base, vehicles=base.vehicles[:1])
        self.swarm = PlumeSwarmEnv(
            one,
            backend=backend,
            attach=attach,
            ticks_per_step=ticks_per_step,
            k_peers=0,
            max_speed_xy_m_s=max_speed_xy_m_s,
            max_speed_z_m_s=max_speed_z_m_s,
            max_yaw_rate_deg_s=max_yaw_rate_deg_s,
            reward_fn=reward_fn,
            termination_fn=termination_fn,
            render_mode=render_mode,
        )
        self.agent = self.swarm.possible_agents[0]
        self.observation_space = self.swarm.observation_space(self.agent)  # type: ignore[assignment]
        self.action_space = self.swarm.action_space(self.agent)  # type: ignore[assignment]
        self.render_mode = render_mode

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Obs, dict[str, Any]]:
        super().reset(seed=seed)
        # The swarm env draws from its own generator, seeded from ours: one seed decides all.
        observations, infos = self.swarm.reset(
            seed=int(self.np_random.integers(2**63 - 1)), options=options
        )
        return observations[self.agent], infos[self.agent]

    def step(self, action: Action) -> tuple[Obs, float, bool, bool, dict[str, Any]]:
        if not self.swarm.agents:
            raise RuntimeError("step() after the episode ended: call reset()")
        obs, rewards, terminated, truncated, infos = self.swarm.step(
            {self.agent: np.asarray(action)}
        )
        a = self.agent
        return obs[a], rewards[a], terminated[a], truncated[a], infos[a]

    def render(self) -> Any:
        return self.swarm.render()

    def close(self) -> None:
        self.swarm.close()
