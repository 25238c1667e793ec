"""A scripted policy on the Gymnasium environment: cast across the wind, surge up it on gas.

No training and no import of plumeswarm: Gymnasium imports the module named before the colon.
Runs in about 2 s (`pip install 'plumeswarm[rl]'`).
"""

import gymnasium
import numpy as np

env = gymnasium.make("plumeswarm.envs:plumeswarm/PlumeSource-v0")
obs, info = env.reset(seed=7)
side, total, done = 1.0, 0.0, False
while not done:
    x, y, z = obs[0:3]
    wind_xy = obs[6:8]
    upwind = -wind_xy / np.linalg.norm(wind_xy)
    across = np.array([-upwind[1], upwind[0]])
    if obs[9] > 0.0:  # gas now: surge upwind, drifting back toward where the plume is
        move = 0.8 * upwind + 0.2 * side * across
    else:  # no gas: cast across the wind, turning at 12 m either side of the axis
        if side * (across @ np.array([x, y])) > 12.0:
            side = -side
        move = 0.9 * side * across + 0.1 * upwind
    climb = np.clip(0.5 * (10.0 - z), -1.0, 1.0)  # hold 10 m, the release height
    action = np.array([move[0], move[1], climb, 0.0], dtype=np.float32)
    obs, reward, terminated, truncated, info = env.step(action)
    total += float(reward)
    done = terminated or truncated
outcome = "found the source" if info["success"] else "did not find the source"
t_s, distance_m = info["sim_time_s"], info["distance_m"]
print(f"{outcome} at t = {t_s:.1f} s, {distance_m:.1f} m away, return {total:.1f}")
env.close()
