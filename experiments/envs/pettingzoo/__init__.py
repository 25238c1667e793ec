"""PettingZoo environments, one versioned module each (PettingZoo's convention)::

from experiments.envs.pettingzoo import plume_swarm_v0

env = plume_swarm_v0.parallel_env(vehicles=4)  # ParallelEnv
aec = plume_swarm_v0.env()  # AECEnv, through PettingZoo's parallel_to_aec
"""

from experiments.envs.pettingzoo import plume_swarm_v0

__all__ = ["plume_swarm_v0"]
