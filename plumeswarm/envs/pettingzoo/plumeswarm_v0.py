"""``plumeswarm_v0``: one agent per vehicle searching for the plume's source (docs/envs.md).

``parallel_env(**kwargs)`` is :class:`~plumeswarm.envs.swarm.PlumeSwarmEnv` (a ``ParallelEnv``);
``env(**kwargs)`` the same as an ``AECEnv`` (agents act in turn), through PettingZoo's
``parallel_to_aec``. Keyword arguments are the environment's: ``scenario``,
``scenario_overrides``, ``vehicles``, ``backend``, ``k_peers``, ``render_mode``, ...
"""

from __future__ import annotations

from typing import Any

from pettingzoo.utils.conversions import parallel_to_aec

from plumeswarm.envs.swarm import PlumeSwarmEnv


def parallel_env(**kwargs: Any) -> PlumeSwarmEnv:
    return PlumeSwarmEnv(**kwargs)


def raw_env(**kwargs: Any) -> Any:
    return parallel_to_aec(PlumeSwarmEnv(**kwargs))


def env(**kwargs: Any) -> Any:
    """The AEC form (PettingZoo's ``env()``)."""
    return raw_env(**kwargs)


__all__ = ["env", "parallel_env", "raw_env"]
