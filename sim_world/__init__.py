"""sim_world — the physics process (pybullet, sim clock, lockstep) and the meshcat viewer."""
