"""The simulated world: one pybullet DIRECT client, a ground plane and the scenario's vehicles.

No bus here: the physics node drives a :class:`World` with :meth:`World.apply` (rotor commands
of one vehicle), :meth:`World.step` (physics substeps) and :meth:`World.states` (ground truth).

Forces per vehicle and substep (conventions in the team notes and ``docs/physics.md``):

- rotor ``i`` runs at ``omega_i``, which follows its target ``u_i * max_rotor_speed`` with a
  first-order lag (exact discretisation, so a zero time constant means instant response);
- thrust ``k_f * omega_i**2`` along body +z at the rotor's position, i.e. a body force plus the
  torque ``r_i x f_i``; reaction torque ``-spin_i * k_m * omega_i**2`` about body z;
- linear drag ``-D * v_air`` in body axes, ``v_air = R^T (v - wind)`` with the scenario's wind
  (``plume_atmosphere.wind``; a time-varying wind is evaluated at each vehicle's position at the
  start
  of every :meth:`World.step` call, i.e. once per control tick, and held over its substeps);
- gravity from pybullet; pybullet's own velocity damping is switched off.

A fixed-wing vehicle (``kind = "fixed_wing"``) has no rotors: its four actuator channels are
throttle (0..1, through the motor lag) and aileron, elevator, rudder (0..1 → −max..+max
deflection, 0.5 neutral, instant), and its force and moment are Beard & McLain's aerodynamics
and propeller (:mod:`sim_world.aero`) from its velocity relative to the same wind, evaluated
every substep. Its touchdown is a crash when it sinks faster than the crash speed (its
forward speed on a runway is no crash).

The per-substep loop is plain scalar Python (numpy on 3-vectors costs more than it saves), with
one force and one torque call per vehicle, both in the body frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from plume_atmosphere.wind import wind_from_scenario, wind_vector_enu
from sim_world.aero import fixed_wing_wrench
from sim_world.checkpoint import CheckpointError, VehicleCheckpoint, WorldCheckpoint, scratch_file
from sim_world.geodesy import EnuToGeodetic
from sim_world.pybullet_quiet import pb
from swarmbus.closeable import Closeable
from swarmbus.messages import VehicleState
from swarmbus.scenario import Scenario, VehicleSpec
from swarmbus.vehicle_types import FixedWing, VehicleType, load_vehicle_type

__all__ = ["GRAVITY_M_S2", "World", "rotate_to_body", "wind_vector_enu"]

GRAVITY_M_S2 = 9.81
# pybullet reports contact points within its collision margin; closer than this is touching.
CONTACT_DISTANCE_M = 5e-3
# Rotor speeds this close to their target snap to it, so settled motors (idle on the ground,
# open-loop hover) skip the motor maths: 1e-6 rad/s changes thrust by ~1e-9 relative.
MOTOR_SNAP_RAD_S = 1e-6
# Bullet's default is 50; resting and landing boxes need far fewer, and with many vehicles on
# the ground the contact solver is most of the step's cost (128 grounded: ~2x faster at 10).
SOLVER_ITERATIONS = 10
_ORIGIN = (0.0, 0.0, 0.0)


def rotate_to_body(
    q: Sequence[float], vx: float, vy: float, vz: float
) -> tuple[float, float, float]:
    """``R(q)^T v``: a world vector in the body frame of attitude ``q`` (x, y, z, w)."""
    # Rotation by the conjugate quaternion: v' = v + w t + u x t with u = -q.xyz, t = 2 u x v.
    ux, uy, uz, w = -q[0], -q[1], -q[2], q[3]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return (
        vx + w * tx + uy * tz - uz * ty,
        vy + w * ty + uz * tx - ux * tz,
        vz + w * tz + ux * ty - uy * tx,
    )


class _Vehicle:
    """Mutable per-vehicle simulation state (plain attributes: this sits in the hot loop)."""

    __slots__ = (
        "aero",
        "body",
        "crash_speed_m_s",
        "crashed",
        "drag",
        "half_height_m",
        "id",
        "in_contact",
        "k_f",
        "k_m",
        "max_speed2",
        "motor_alpha",
        "motors_enabled",
        "neutral",
        "omega",
        "omega_max",
        "on_ground",
        "rotor_x",
        "rotor_y",
        "settled",
        "spin",
        "target",
        "type",
        "wrench",
    )

    def __init__(self, spec: VehicleSpec, vtype: VehicleType, body: int, crash_speed: float):
        self.id = spec.id
        self.type = vtype
        self.body = body
        n = vtype.actuator_count
        self.aero: FixedWing | None = vtype.fixed_wing
        # the actuators' rest position: motors off (a fixed wing: surfaces centred)
        self.neutral = [0.0] * n if self.aero is None else [0.0, 0.5, 0.5, 0.5]
        self.rotor_x = [r.position_m[0] for r in vtype.rotors]
        self.rotor_y = [r.position_m[1] for r in vtype.rotors]
        self.spin = [float(r.spin) for r in vtype.rotors]
        self.k_f = vtype.thrust_coeff_n_per_rad2_s2
        self.k_m = vtype.torque_coeff_nm_per_rad2_s2
        self.omega_max = vtype.max_rotor_speed_rad_s
        self.drag = vtype.linear_drag_n_per_m_s
        self.half_height_m = vtype.collision_half_extents_m[2]
        self.motor_alpha = 1.0  # set by World from the physics step
        self.omega = list(self.neutral)
        self.target = list(self.neutral)
        # Motors at their targets: the body-frame thrust and torque are constant (cached).
        self.settled = True
        self.wrench = (0.0, 0.0, 0.0, 0.0)
        self.motors_enabled = True
        self.crash_speed_m_s = crash_speed
        self.crashed = False
        self.on_ground = False
        self.in_contact = False
        self.max_speed2 = 0.0


# The vehicle state a checkpoint carries as it is (same name on _Vehicle and VehicleCheckpoint):
# one list for both ways, so that a field saved is a field restored.
_CHECKPOINTED = (
    "settled",
    "wrench",
    "motors_enabled",
    "crashed",
    "on_ground",
    "in_contact",
    "max_speed2",
)


def _spin_motors(v: _Vehicle) -> tuple[float, float, float, float]:
    """One motor-lag step; the body-frame thrust and torque (x, y, z) of the new speeds."""
    alpha = v.motor_alpha
    k_f = v.k_f
    k_m = v.k_m
    omega = v.omega
    target = v.target
    rx = v.rotor_x
    ry = v.rotor_y
    spin = v.spin
    thrust = tx = ty = tz = 0.0
    settled = True
    for i in range(len(omega)):
        w = omega[i]
        diff = target[i] - w
        if -MOTOR_SNAP_RAD_S < diff < MOTOR_SNAP_RAD_S:
            w = target[i]
        else:
            w += diff * alpha
            settled = False
        omega[i] = w
        w2 = w * w
        f = k_f * w2
        thrust += f
        tx += ry[i] * f
        ty -= rx[i] * f
        tz -= spin[i] * k_m * w2
    wrench = (thrust, tx, ty, tz)
    if settled:
        v.settled = True
        v.wrench = wrench
    return wrench


class World(Closeable):
    """All vehicles of a scenario in one pybullet DIRECT client; use as a context manager."""

    def __init__(
        self,
        scenario: Scenario,
        vehicle_types: Mapping[str, VehicleType] | None = None,
    ) -> None:
        """``vehicle_types`` overrides types by name (tests); others load from files."""
        self.scenario = scenario
        self.physics_hz = scenario.time.physics_hz
        self.dt_s = 1.0 / self.physics_hz
        self.wind_enu_m_s = wind_vector_enu(scenario.wind.speed_m_s, scenario.wind.from_deg)
        self.wind = wind_from_scenario(scenario)
        origin = scenario.world.origin
        self._geodetic = EnuToGeodetic(origin.lat_deg, origin.lon_deg, origin.alt_m)
        self.step_count = 0
        self._fresh: list[tuple[Sequence[float], Sequence[float]]] = []
        self._fresh_step = -1
        self._client = pb.connect(pb.DIRECT)
        try:
            self._build(vehicle_types or {})
        except BaseException:
            pb.disconnect(physicsClientId=self._client)
            raise

    # ------------------------------------------------------------------ construction
    def _build(self, overrides: Mapping[str, VehicleType]) -> None:
        c = self._client
        pb.setGravity(0.0, 0.0, -GRAVITY_M_S2, physicsClientId=c)
        pb.setTimeStep(self.dt_s, physicsClientId=c)
        pb.setPhysicsEngineParameter(numSolverIterations=SOLVER_ITERATIONS, physicsClientId=c)
        plane = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=c)
        self.ground_body = pb.createMultiBody(0.0, plane, -1, _ORIGIN, physicsClientId=c)
        self._vehicles: list[_Vehicle] = []
        self._by_id: dict[str, _Vehicle] = {}
        self._by_body: dict[int, _Vehicle] = {}
        shapes: dict[str, int] = {}
        for spec in self.scenario.vehicles:
            vtype = overrides.get(spec.type) or load_vehicle_type(spec.type)
            if spec.type not in shapes:
                shapes[spec.type] = pb.createCollisionShape(
                    pb.GEOM_BOX, halfExtents=list(vtype.collision_half_extents_m), physicsClientId=c
                )
            x, y, z = spec.spawn_enu_m
            position = (x, y, z + vtype.collision_half_extents_m[2])
            attitude = pb.getQuaternionFromEuler(
                (0.0, 0.0, math.radians(spec.spawn_yaw_deg)), physicsClientId=c
            )
            body = pb.createMultiBody(
                vtype.mass_kg, shapes[spec.type], -1, position, attitude, physicsClientId=c
            )
            pb.changeDynamics(
                body,
                -1,
                linearDamping=0.0,
                angularDamping=0.0,
                localInertiaDiagonal=list(vtype.inertia_kg_m2),
                physicsClientId=c,
            )
            crash_speed = self.scenario.failsafe_for(spec.id).crash_speed_m_s
            v = _Vehicle(spec, vtype, body, crash_speed)
            tau = vtype.motor_time_constant_s
            v.motor_alpha = 1.0 - math.exp(-self.dt_s / tau) if tau > 0.0 else 1.0
            self._vehicles.append(v)
            self._by_id[spec.id] = v
            self._by_body[body] = v
        pb.performCollisionDetection(physicsClientId=c)
        self._update_contacts()
        for v in self._vehicles:
            v.in_contact = v.on_ground  # resting at spawn is not an impact

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        if self._client >= 0:
            pb.disconnect(physicsClientId=self._client)
            self._client = -1

    # ------------------------------------------------------------------ inputs
    @property
    def vehicle_ids(self) -> tuple[str, ...]:
        return tuple(v.id for v in self._vehicles)

    @property
    def sim_time_s(self) -> float:
        return self.step_count / self.physics_hz

    @property
    def pybullet_bodies(self) -> tuple[int, tuple[int, ...]]:
        """The pybullet client and every vehicle's body, in scenario order (for benches)."""
        return self._client, tuple(v.body for v in self._vehicles)

    def vehicle_type(self, vehicle_id: str) -> VehicleType:
        return self._by_id[vehicle_id].type

    def apply(self, vehicle_id: str, rotor_commands: Sequence[float]) -> None:
        """Set the rotor speed targets of a vehicle: ``u`` in [0, 1] of max rotor speed.

        Raises ``KeyError`` for an unknown vehicle and ``ValueError`` for a wrong rotor count.
        """
        self._apply(self._by_id[vehicle_id], rotor_commands)

    def _apply(self, v: _Vehicle, rotor_commands: Sequence[float]) -> None:
        target = v.target
        if len(rotor_commands) != len(target):
            raise ValueError(
                f"vehicle {v.id!r} has {len(target)} rotors, got {len(rotor_commands)} "
                "rotor commands"
            )
        omega_max = v.omega_max if v.aero is None else 1.0  # a fixed wing's are fractions
        enabled = v.motors_enabled
        neutral = v.neutral
        for i, u in enumerate(rotor_commands):
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else float(u))
            w = u * omega_max if enabled else neutral[i]
            if w != target[i]:
                target[i] = w
                v.settled = False

    def apply_tick(self, commands: Mapping[str, Sequence[float]]) -> list[str]:
        """A tick's commands of every vehicle: a vehicle without one (no answer, a dropped
        participant) or with a bad one gets its motors off. Returns one line per bad command."""
        bad = []
        for v in self._vehicles:
            cmd = commands.get(v.id)
            if cmd is None:
                self.set_motors_enabled(v.id, False)
                continue
            v.motors_enabled = True
            try:
                self._apply(v, cmd)
            except ValueError as exc:
                bad.append(str(exc))
                self.set_motors_enabled(v.id, False)
        return bad

    def set_motors_enabled(self, vehicle_id: str, enabled: bool) -> None:
        """Disabled motors get zero targets until enabled again (a dropped participant)."""
        v = self._by_id[vehicle_id]
        v.motors_enabled = enabled
        if not enabled:
            v.target[:] = v.neutral
            v.settled = False

    def set_rotor_speeds(self, vehicle_id: str, omega_rad_s: Sequence[float]) -> None:
        """Initial condition: rotors already spinning at ``omega_rad_s`` (and targeting it)."""
        v = self._by_id[vehicle_id]
        if len(omega_rad_s) != len(v.omega):
            raise ValueError(f"vehicle {vehicle_id!r} has {len(v.omega)} rotors")
        v.omega[:] = [float(w) for w in omega_rad_s]
        v.target[:] = [float(w) for w in omega_rad_s]
        v.settled = False

    def set_motion(
        self,
        vehicle_id: str,
        position_enu_m: Sequence[float],
        velocity_enu_m_s: Sequence[float],
        yaw_deg: float = 0.0,
        pitch_deg: float = 0.0,
    ) -> None:
        """Initial condition: the body's centre at ``position_enu_m`` moving at
        ``velocity_enu_m_s``, heading ``yaw_deg`` (ENU) and pitched ``pitch_deg`` nose up, not
        rotating (a fixed wing in flight, a hand launch)."""
        v = self._by_id[vehicle_id]
        c = self._client
        q = pb.getQuaternionFromEuler(
            (0.0, -math.radians(pitch_deg), math.radians(yaw_deg)), physicsClientId=c
        )
        pb.resetBasePositionAndOrientation(v.body, list(position_enu_m), q, physicsClientId=c)
        pb.resetBaseVelocity(v.body, list(velocity_enu_m_s), [0.0, 0.0, 0.0], physicsClientId=c)
        self._fresh_step = -1

    def rotor_speeds(self, vehicle_id: str) -> tuple[float, ...]:
        return tuple(self._by_id[vehicle_id].omega)

    # ------------------------------------------------------------------ stepping
    def _winds(self, get_pose: Any) -> list[tuple[float, float, float]]:
        """Each vehicle's air velocity for this step call (the wind at the call's sim time)."""
        if self.wind.steady:
            return [self.wind_enu_m_s] * len(self._vehicles)
        uniform = self.wind.uniform_at(self.step_count * self.dt_s)
        if uniform is not None:
            return [uniform] * len(self._vehicles)
        c = self._client
        points = [get_pose(v.body, physicsClientId=c)[0] for v in self._vehicles]
        values = self.wind.velocity(points, self.step_count * self.dt_s)
        return [(float(w[0]), float(w[1]), float(w[2])) for w in values]

    def step(self, n: int = 1) -> None:
        """Advance ``n`` physics steps, then update contacts, landed and crashed flags."""
        c = self._client
        get_pose = pb.getBasePositionAndOrientation
        get_vel = pb.getBaseVelocity
        force = pb.applyExternalForce
        torque = pb.applyExternalTorque
        link_frame = pb.LINK_FRAME
        step_sim = pb.stepSimulation
        vehicles = self._vehicles
        winds = self._winds(get_pose)
        # What states() read since the last step is what the first substep would read again.
        fresh = self._fresh if self._fresh_step == self.step_count else None
        for _ in range(n):
            for i, v in enumerate(vehicles):
                body = v.body
                if fresh is None:
                    q = get_pose(body, physicsClientId=c)[1]
                    (vx, vy, vz) = get_vel(body, physicsClientId=c)[0]
                else:
                    q, (vx, vy, vz) = fresh[i]
                if v.aero is not None:
                    self._fly_fixed_wing(v, q, vx, vy, vz, winds[i])
                    continue
                speed2 = vx * vx + vy * vy + vz * vz
                if speed2 > v.max_speed2:
                    v.max_speed2 = speed2
                if v.settled:
                    thrust, tx, ty, tz = v.wrench
                else:
                    thrust, tx, ty, tz = _spin_motors(v)
                # Drag against the air, in body axes.
                wx, wy, wz = winds[i]
                bx, by, bz = rotate_to_body(q, vx - wx, vy - wy, vz - wz)
                dx, dy, dz = v.drag
                force(
                    body,
                    -1,
                    (-dx * bx, -dy * by, thrust - dz * bz),
                    _ORIGIN,
                    link_frame,
                    physicsClientId=c,
                )
                if tx or ty or tz:  # idle motors: no torque call
                    torque(body, -1, (tx, ty, tz), link_frame, physicsClientId=c)
            step_sim(physicsClientId=c)
            self.step_count += 1
            fresh = None
        self._update_contacts()

    def _fly_fixed_wing(
        self,
        v: _Vehicle,
        q: Sequence[float],
        vx: float,
        vy: float,
        vz: float,
        wind: tuple[float, float, float],
    ) -> None:
        """One substep's aerodynamic and propeller wrench on a fixed wing (body frame)."""
        assert v.aero is not None
        c = self._client
        if vz < 0.0 and vz * vz > v.max_speed2:  # a fixed wing crashes on its sink rate
            v.max_speed2 = vz * vz
        omega = v.omega
        target = v.target
        omega[0] += (target[0] - omega[0]) * v.motor_alpha
        omega[1:] = target[1:]
        limits = v.aero.max_deflection_deg
        surfaces = [math.radians(limits[k]) * (2.0 * omega[k + 1] - 1.0) for k in range(3)]
        ang = pb.getBaseVelocity(v.body, physicsClientId=c)[1]
        air = rotate_to_body(q, vx - wind[0], vy - wind[1], vz - wind[2])
        fx, fy, fz, tx, ty, tz = fixed_wing_wrench(
            v.aero, omega[0], surfaces, air, rotate_to_body(q, *ang)
        )
        pb.applyExternalForce(v.body, -1, (fx, fy, fz), _ORIGIN, pb.LINK_FRAME, physicsClientId=c)
        pb.applyExternalTorque(v.body, -1, (tx, ty, tz), pb.LINK_FRAME, physicsClientId=c)

    def _update_contacts(self) -> None:
        ground = self.ground_body
        by_body = self._by_body
        touching_ground: set[int] = set()
        for contact in pb.getContactPoints(physicsClientId=self._client):
            if contact[8] > CONTACT_DISTANCE_M:
                continue
            a, b = contact[1], contact[2]
            if a == ground or b == ground:
                touching_ground.add(b if a == ground else a)
            elif a in by_body and b in by_body:
                by_body[a].crashed = True
                by_body[b].crashed = True
        for v in self._vehicles:
            touching = v.body in touching_ground
            if touching and not v.in_contact and v.max_speed2 > v.crash_speed_m_s**2:
                v.crashed = True
            v.in_contact = touching
            v.on_ground = touching
            v.max_speed2 = 0.0

    # ------------------------------------------------------------------ checkpoints
    def checkpoint(self, tick: int) -> WorldCheckpoint:
        """Everything needed to continue identically from here (``tick`` is the caller's)."""
        c = self._client
        scratch = scratch_file(".bullet")
        try:
            pb.saveBullet(str(scratch), physicsClientId=c)
            bullet = scratch.read_bytes()
        finally:
            scratch.unlink(missing_ok=True)
        vehicles = []
        for v in self._vehicles:
            pos, q = pb.getBasePositionAndOrientation(v.body, physicsClientId=c)
            lin, ang = pb.getBaseVelocity(v.body, physicsClientId=c)
            vehicles.append(
                VehicleCheckpoint(
                    vehicle_id=v.id,
                    vehicle_type=v.type.name,
                    omega_rad_s=list(v.omega),
                    target_rad_s=list(v.target),
                    **{name: getattr(v, name) for name in _CHECKPOINTED},
                    position_enu_m=pos,
                    attitude_xyzw=q,
                    velocity_enu_m_s=lin,
                    angular_velocity_enu_rad_s=ang,
                )
            )
        return WorldCheckpoint(
            world=self.scenario.world.name,
            physics_hz=self.physics_hz,
            control_hz=self.scenario.time.control_hz,
            tick=tick,
            step_count=self.step_count,
            sim_time_s=self.sim_time_s,
            vehicles=vehicles,
            bullet=bullet,
        )

    def restore(self, cp: WorldCheckpoint) -> None:
        """Continue from ``cp`` (a checkpoint of this scenario's world); CheckpointError if not."""
        mine = [(v.id, v.type.name) for v in self._vehicles]
        theirs = [(v.vehicle_id, v.vehicle_type) for v in cp.vehicles]
        rates = (self.physics_hz, self.scenario.time.control_hz)
        if (
            cp.world != self.scenario.world.name
            or theirs != mine
            or (cp.physics_hz, cp.control_hz) != rates
        ):
            raise CheckpointError(
                f"the checkpoint is of world {cp.world!r} with vehicles {theirs} at "
                f"{cp.physics_hz}/{cp.control_hz} Hz; this scenario is "
                f"{self.scenario.world.name!r} with {mine} at {rates[0]}/{rates[1]} Hz"
            )
        c = self._client
        scratch = scratch_file(".bullet")
        try:
            scratch.write_bytes(cp.bullet)
            pb.restoreState(fileName=str(scratch), physicsClientId=c)
        except pb.error as exc:
            raise CheckpointError(f"pybullet could not restore the checkpoint: {exc}") from None
        finally:
            scratch.unlink(missing_ok=True)
        for v, saved in zip(self._vehicles, cp.vehicles, strict=True):
            pos, q = pb.getBasePositionAndOrientation(v.body, physicsClientId=c)
            if pos != saved.position_enu_m or q != saved.attitude_xyzw:
                raise CheckpointError(
                    f"restored {v.id} at {pos} {q}, the checkpoint says "
                    f"{saved.position_enu_m} {saved.attitude_xyzw}"
                )
            v.omega[:] = saved.omega_rad_s
            v.target[:] = saved.target_rad_s
            for name in _CHECKPOINTED:
                setattr(v, name, getattr(saved, name))
        self.step_count = cp.step_count
        self._fresh_step = -1

    # ------------------------------------------------------------------ outputs
    def states(self, tick: int, sim_time_s: float | None = None) -> list[VehicleState]:
        """Ground truth of every vehicle, in scenario order."""
        c = self._client
        t = self.sim_time_s if sim_time_s is None else sim_time_s
        geodetic = self._geodetic
        fresh = []
        out = []
        for v in self._vehicles:
            pos, q = pb.getBasePositionAndOrientation(v.body, physicsClientId=c)
            lin, ang = pb.getBaseVelocity(v.body, physicsClientId=c)
            fresh.append((q, lin))
            lat, lon, alt = geodetic(pos[0], pos[1], pos[2])
            out.append(
                VehicleState(
                    vehicle_id=v.id,
                    tick=tick,
                    sim_time_s=t,
                    position_enu_m=pos,
                    velocity_enu_m_s=lin,
                    attitude_xyzw=q,
                    body_rates_rad_s=rotate_to_body(q, *ang),
                    lat_deg=lat,
                    lon_deg=lon,
                    alt_m=alt,
                    on_ground=v.on_ground,
                    crashed=v.crashed,
                    motors_enabled=v.motors_enabled,
                )
            )
        self._fresh = fresh
        self._fresh_step = self.step_count
        return out
