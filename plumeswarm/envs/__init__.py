"""Gymnasium and PettingZoo environments over plumeswarm (docs/envs.md).

Importing this module registers the ``plumeswarm/...`` ids with Gymnasium;
``gymnasium.make("plumeswarm.envs:plumeswarm/PlumeSource-v0")`` imports it itself.
"""

# ruff: noqa: E402 - the extra is checked before its modules are imported

from __future__ import annotations

from swarmbus.extras import require

require("plumeswarm.envs", "gymnasium", "pettingzoo", "matplotlib")

import gymnasium
from gymnasium.envs.registration import get_env_id, namespace

from plumeswarm.envs.central import PlumeSwarmCentralEnv
from plumeswarm.envs.source import PlumeSourceEnv
from plumeswarm.envs.swarm import AgentStep, PlumeSwarmEnv, default_reward, default_termination
from plumeswarm.experiments.driver import BusDriver, InProcessDriver

NAMESPACE = "plumeswarm"
ENV_ID = get_env_id(NAMESPACE, "PlumeSource", 0)  # Gymnasium's spelling: namespace/name-vN

# name -> (entry point, keyword arguments): every id of the namespace (docs/envs.md).
ENVIRONMENTS: dict[str, tuple[str, dict[str, object]]] = {
    "PlumeSource-v0": ("plumeswarm.envs.source:PlumeSourceEnv", {}),
    "PlumeSourceFilament-v0": ("plumeswarm.envs.source:PlumeSourceEnv", {"scenario": "filament"}),
    "PlumeSourceMox-v0": (
        "plumeswarm.envs.source:PlumeSourceEnv",
        {"scenario_overrides": ("sensor.preset=mox-tgs2620",)},
    ),
    "PlumeSwarm-v0": ("plumeswarm.envs.central:PlumeSwarmCentralEnv", {}),
}
ENV_IDS = [f"{NAMESPACE}/{name}" for name in ENVIRONMENTS]


def register_envs() -> None:
    """Register every ``plumeswarm/...`` id with Gymnasium (done on import; idempotent)."""
    with namespace(NAMESPACE):
        for name, (entry_point, kwargs) in ENVIRONMENTS.items():
            if f"{NAMESPACE}/{name}" not in gymnasium.registry:
                gymnasium.register(id=name, entry_point=entry_point, kwargs=kwargs)


register_envs()


def parallel_env(**kwargs: object) -> PlumeSwarmEnv:
    """The PettingZoo ``ParallelEnv`` (PettingZoo's naming); see :class:`PlumeSwarmEnv`."""
    return PlumeSwarmEnv(**kwargs)  # type: ignore[arg-type]


__all__ = [
    "ENV_ID",
    "ENV_IDS",
    "AgentStep",
    "BusDriver",
    "InProcessDriver",
    "PlumeSourceEnv",
    "PlumeSwarmCentralEnv",
    "PlumeSwarmEnv",
    "default_reward",
    "default_termination",
    "parallel_env",
    "register_envs",
]
