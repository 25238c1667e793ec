"""Three agents, one per vehicle, on the PettingZoo parallel environment: each surges upwind when
it smells gas, flies toward a peer that smells it, and casts across the wind otherwise.

Each agent's return telescopes (the default reward is metres of progress toward the source,
+10 on finding it, -10 on a crash or a geofence exit): start distance - end distance + 10 * found.
"""

import numpy as np

from plumeswarm.envs.pettingzoo import plumeswarm_v0

env = plumeswarm_v0.parallel_env(k_peers=2)
observations, infos = env.reset(seed=3)
start_m = {a: info["distance_m"] for a, info in infos.items()}
returns = dict.fromkeys(env.possible_agents, 0.0)
last = dict(infos)
sides = {a: 1.0 if i % 2 else -1.0 for i, a in enumerate(env.possible_agents)}
# one altitude each, 1.5 m apart around the release height: agents that meet do not collide
altitude_m = {a: 10.0 + 1.5 * (i - 1) for i, a in enumerate(env.possible_agents)}
while env.agents:
    actions = {}
    for agent in env.agents:
        obs = observations[agent]
        x, y, z = obs[0:3]
        upwind = -obs[6:8] / np.linalg.norm(obs[6:8])
        across = np.array([-upwind[1], upwind[0]])
        # peer j: relative position obs[10+5j : 13+5j], reading obs[13+5j] (docs/envs.md)
        smelling = [obs[10 + 5 * j : 12 + 5 * j] for j in range(2) if obs[13 + 5 * j] > 0.0]
        if obs[9] > 0.0:
            move = 0.8 * upwind + 0.2 * sides[agent] * across
        elif smelling:  # line up across the wind with the peer, and go upwind
            move = 0.6 * upwind + 0.4 * np.sign(across @ smelling[0]) * across
        else:
            if sides[agent] * (across @ np.array([x, y])) > 12.0:
                sides[agent] = -sides[agent]
            move = 0.9 * sides[agent] * across + 0.1 * upwind
        climb = np.clip(0.5 * (altitude_m[agent] - z), -1.0, 1.0)
        actions[agent] = np.array([move[0], move[1], climb, 0.0], dtype=np.float32)
    observations, rewards, terminated, truncated, infos = env.step(actions)
    for agent, reward in rewards.items():
        returns[agent] += reward
        last[agent] = infos[agent]
for agent in env.possible_agents:
    info = last[agent]
    print(
        f"{agent}: start {start_m[agent]:.2f} m, end {info['distance_m']:.2f} m, "
        f"found {info['success']}, crashed {info['crashed']}, return {returns[agent]:.2f}"
    )
env.close()
