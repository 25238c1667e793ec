"""Gymnasium and PettingZoo environments over plumeswarm (docs/envs.md).

Importing this module registers ``plumeswarm/PlumeSource-v0`` with Gymnasium.
"""

# ruff: noqa: E402 - the extra is checked before its modules are imported

from __future__ import annotations

from swarmbus.extras import require

require("the environments", "gymnasium", "pettingzoo", "matplotlib")

import gymnasium
from gymnasium.envs.registration import get_env_id, namespace

from experiments.driver import BusDriver, InProcessDriver
from experiments.envs.source import PlumeSourceEnv
from experiments.envs.swarm import AgentStep, PlumeSwarmEnv, default_reward, default_termination

NAMESPACE = "plumeswarm"
ENV_ID = get_env_id(NAMESPACE, "PlumeSource", 0)  # Gymnasium's spelling: namespace/name-vN

if ENV_ID not in gymnasium.registry:
    with namespace(NAMESPACE):
        gymnasium.register(
            id="PlumeSource-v0", entry_point="experiments.envs.source:PlumeSourceEnv"
        )


def parallel_env(**kwargs: object) -> PlumeSwarmEnv:
    """The PettingZoo ``ParallelEnv`` (PettingZoo's naming); see :class:`PlumeSwarmEnv`."""
    return PlumeSwarmEnv(**kwargs)  # type: ignore[arg-type]


__all__ = [
    "ENV_ID",
    "AgentStep",
    "BusDriver",
    "InProcessDriver",
    "PlumeSourceEnv",
    "PlumeSwarmEnv",
    "default_reward",
    "default_termination",
    "parallel_env",
]
