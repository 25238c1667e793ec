"""The pybullet floor: what the same bodies cost pybullet alone, for ``plumeswarm bench envs``.

The scenario's world (:class:`~sim_world.world.World`: its ground plane, its vehicles' boxes,
masses and inertias, the physics rate and solver settings) with every vehicle lifted 10 m above
its spawn point, at rest. Then, per physics step and per vehicle: one pose and one velocity
read, one force (its weight, so it stays where it is) and one torque, both in the body frame;
then one ``stepSimulation``. No control, no sensing, no wind, no states: a lower bound on
what any simulator stepping these bodies through pybullet's Python API pays per tick.
"""

from __future__ import annotations

import time
from typing import Any

from sim_world.pybullet_quiet import pb
from sim_world.world import GRAVITY_M_S2, World
from swarmbus.scenario import Scenario

LIFT_M = 10.0


def floor_row(scenario: Scenario, ticks: int) -> dict[str, Any]:
    """Step ``ticks`` control ticks (``scenario.substeps`` physics steps each) of the floor;
    wall and CPU seconds and the sim seconds they stepped."""
    with World(scenario) as world:
        for spec in scenario.vehicles:
            x, y, z = spec.spawn_enu_m
            world.set_motion(spec.id, (x, y, z + LIFT_M), (0.0, 0.0, 0.0), spec.spawn_yaw_deg)
        c, bodies = world.pybullet_bodies
        weights = [
            (0.0, 0.0, world.vehicle_type(spec.id).mass_kg * GRAVITY_M_S2)
            for spec in scenario.vehicles
        ]
        load = list(zip(bodies, weights, strict=True))
        get_pose, get_vel = pb.getBasePositionAndOrientation, pb.getBaseVelocity
        force, torque, step_sim = pb.applyExternalForce, pb.applyExternalTorque, pb.stepSimulation
        frame, origin, still = pb.LINK_FRAME, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0)
        steps = ticks * scenario.substeps
        t0, cpu0 = time.perf_counter(), time.process_time()
        for _ in range(steps):
            for body, weight in load:
                get_pose(body, physicsClientId=c)
                get_vel(body, physicsClientId=c)
                force(body, -1, weight, origin, frame, physicsClientId=c)
                torque(body, -1, still, frame, physicsClientId=c)
            step_sim(physicsClientId=c)
        wall, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    return {"wall_s": wall, "cpu_s": cpu, "sim_s": steps / scenario.time.physics_hz}
