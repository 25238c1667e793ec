"""PettingZoo environments, one versioned module each (PettingZoo's convention)::

from plumeswarm.envs.pettingzoo import plumeswarm_v0

env = plumeswarm_v0.parallel_env(vehicles=4)  # ParallelEnv
aec = plumeswarm_v0.env()  # AECEnv, through PettingZoo's parallel_to_aec
"""

from plumeswarm.envs.pettingzoo import plumeswarm_v0

__all__ = ["plumeswarm_v0"]
