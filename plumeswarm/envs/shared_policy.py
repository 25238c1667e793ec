"""Parameter sharing: one Stable-Baselines3 policy flies every agent of the PettingZoo
environment (docs/envs.md, "Multi-agent training").

:func:`agents_vec_env` turns N copies of :class:`~plumeswarm.envs.swarm.PlumeSwarmEnv` into one
SB3 vector environment with a slot per agent of each copy, the way PettingZoo documents it for
SB3: SuperSuit's ``black_death_v3`` (an agent whose episode ended stays in its slot, observing
zeros and earning 0, until every agent of its copy has ended), ``pettingzoo_env_to_vec_env_v1``
(the agents of one copy as a vector) and ``concat_vec_envs_v1`` (N copies, each in its own worker
process; one copy steps in-process). Slot ``c * A + a`` is agent ``a`` of copy ``c`` (A agents a
copy, in ``possible_agents`` order). Needs the ``train`` extra.
"""

# ruff: noqa: E402 - the extra is checked before its modules are imported

from __future__ import annotations

from typing import Any

from swarmbus.extras import require

require("plumeswarm.envs.shared_policy", "stable_baselines3", "supersuit")

import supersuit
from stable_baselines3.common.vec_env import VecEnv
from supersuit.vector.sb3_vector_wrapper import SB3VecEnvWrapper

from plumeswarm.envs.swarm import PlumeSwarmEnv


class SeededAgentsVecEnv(SB3VecEnvWrapper):  # type: ignore[misc]
    """SuperSuit's SB3 wrapper, whose reset does not pass SB3's seed on to the copies: here
    ``seed(s)`` reaches them at the next reset, as SB3's ``VecEnv.seed`` promises."""

    def __init__(self, venv: Any, seed: int | None = None) -> None:
        super().__init__(venv)
        self._next_seed = seed

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._next_seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        if seed is not None:
            self._next_seed = seed
        observations, self.reset_infos = self.venv.reset(seed=self._next_seed, options=options)
        self._next_seed = None
        return observations


def agents_vec_env(envs: int, seed: int, **env_kwargs: Any) -> VecEnv:
    """``envs`` copies of ``PlumeSwarmEnv(**env_kwargs)`` as one SB3 vector environment of
    ``envs * len(possible_agents)`` slots; copy i is seeded with ``seed + i`` at its first reset
    and draws every later episode from that stream."""
    if envs < 1:
        raise ValueError(f"envs: must be >= 1, got {envs}")
    agents = supersuit.pettingzoo_env_to_vec_env_v1(
        supersuit.black_death_v3(PlumeSwarmEnv(**env_kwargs))
    )
    copies = supersuit.concat_vec_envs_v1(agents, envs, num_cpus=envs, base_class="gymnasium")
    return SeededAgentsVecEnv(copies, seed)
