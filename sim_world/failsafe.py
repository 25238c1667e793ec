"""What the physics does with a flying vehicle whose autopilot is silent, in every clock mode.

In lockstep and stepped mode the physics waits for every command (docs/physics.md, "Lockstep")
until its drop rules give a participant up (a partition longer than the grace, a restart
limit); in realtime the world cannot wait past a tick's deadline. Either way a vehicle without
its command is not left to fall: it holds where it is for ``failsafe.hold_s`` (PX4's
``COM_FAIL_ACT_T``, 5 s: the Hold before a failsafe action), then lands there, as PX4's Land
failsafe does: it stops horizontally (velocity held at zero against the wind's drag, within
about 0.5 m/s in a 6 m/s wind) and descends at ``failsafe.descend_speed_m_s`` (PX4's
``MPC_LAND_SPEED``, 0.7 m/s) until it touches the ground; then its motors stop. The controller
uses the vehicle's true state of the tick, as the autopilot would its estimate, and the vehicle
type's inertia, rotors and coefficients. The autopilot, back, finds that ticks were stepped
without it and lands too (``agents.autopilot_node``), as in realtime after a state loss.

A fixed wing cannot hold or descend on the spot: without its autopilot it glides, throttle
off and surfaces centred (the Aerosonde is statically stable: it settles into a glide);
on the ground its throttle stays off.

The episodes are counted per vehicle (:class:`CommandGaps`): how many ticks went without the
vehicle's command, in how many outages, how much sim time under the failsafe; the physics puts
them in its health detail and its last log line ("the run reports what was late").

See docs/physics.md ("The physics' failsafe") and docs/reliability.md
("Partitions between hosts").
"""

from __future__ import annotations

import logging
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from sim_world.world import GRAVITY_M_S2, rotate_to_body
from swarmbus.messages import VehicleState
from swarmbus.scenario import Scenario
from swarmbus.vehicle_types import VehicleType, load_vehicle_type

log = logging.getLogger(__name__)

# Gains of the land controller: velocity error → acceleration (1/s, horizontal and
# vertical), tilt error → angular acceleration (rad/s² per rad: natural frequency 5 rad/s), body
# rate damping (1/s: damping ratio 1), yaw rate damping (1/s).
VELOCITY_XY_P = 2.0
VELOCITY_Z_P = 2.0
ALTITUDE_P = 1.0  # hold: altitude error (m) → vertical speed (m/s), at most the descent speed
TILT_P = 25.0
RATE_D = 10.0
YAW_RATE_D = 4.0
MAX_TILT_RAD = math.radians(30.0)
MIN_THRUST_OF_WEIGHT = 0.3  # collective kept while righting the body, for the torques


class LandController:
    """PX4's Land as a failsafe, for one vehicle type: rotor commands (0..1) from a state."""

    def __init__(self, vtype: VehicleType, descend_speed_m_s: float) -> None:
        self.mass_kg = vtype.mass_kg
        self.inertia = tuple(vtype.inertia_kg_m2)
        self.k_f = vtype.thrust_coeff_n_per_rad2_s2
        self.omega_max = vtype.max_rotor_speed_rad_s
        self.speed_m_s = descend_speed_m_s
        # the air's drag on the descent, carried by the thrust's feed-forward (level, no wind)
        self.drag_accel_m_s2 = vtype.linear_drag_n_per_m_s[2] * descend_speed_m_s / vtype.mass_kg
        ratio = vtype.torque_coeff_nm_per_rad2_s2 / self.k_f
        # wrench (thrust, τx, τy, τz) = A · rotor thrusts, as in sim_world.world
        a = np.array(
            [
                [1.0] * len(vtype.rotors),
                [r.position_m[1] for r in vtype.rotors],
                [-r.position_m[0] for r in vtype.rotors],
                [-float(r.spin) * ratio for r in vtype.rotors],
            ]
        )
        self._mix = np.linalg.pinv(a)

    def _thrust_direction(
        self, state: VehicleState, hold_z_m: float | None
    ) -> tuple[float, float, float]:
        """The specific force wanted (world, m/s²): stop horizontally, descend at the speed (or
        hold ``hold_z_m``); tilted at most MAX_TILT_RAD."""
        vx, vy, vz = state.velocity_enu_m_s
        ax, ay = -VELOCITY_XY_P * vx, -VELOCITY_XY_P * vy
        if hold_z_m is None:
            want_vz, drag = -self.speed_m_s, self.drag_accel_m_s2
        else:
            error = ALTITUDE_P * (hold_z_m - state.position_enu_m[2])
            want_vz, drag = max(-self.speed_m_s, min(self.speed_m_s, error)), 0.0
        az = GRAVITY_M_S2 - drag + VELOCITY_Z_P * (want_vz - vz)
        az = max(az, 0.1 * GRAVITY_M_S2)
        horizontal = math.hypot(ax, ay)
        limit = az * math.tan(MAX_TILT_RAD)
        if horizontal > limit:
            ax, ay = ax * limit / horizontal, ay * limit / horizontal
        return ax, ay, az

    def command(self, state: VehicleState, hold_z_m: float | None = None) -> list[float] | None:
        """The rotor commands of the tick (landing, or holding at ``hold_z_m``); None once on
        the ground or crashed (motors off)."""
        if state.on_ground or state.crashed:
            return None
        q = state.attitude_xyzw
        fx, fy, fz = self._thrust_direction(state, hold_z_m)
        norm = math.sqrt(fx * fx + fy * fy + fz * fz)
        # body up and the wanted direction, both in the body frame
        dx, dy, dz = rotate_to_body(q, fx / norm, fy / norm, fz / norm)
        # the rotation from body up (0, 0, 1) to d: axis (−dy, dx, 0), angle acos(dz)
        sin_angle = math.hypot(dx, dy)
        angle = math.atan2(sin_angle, dz)
        if sin_angle > 1e-9:
            ex, ey = -dy / sin_angle * angle, dx / sin_angle * angle
        else:  # level, or upside down: roll over
            ex, ey = (0.0, 0.0) if dz > 0.0 else (math.pi, 0.0)
        p, r_, yaw_rate = state.body_rates_rad_s
        ix, iy, iz = self.inertia
        torque = (
            ix * (TILT_P * ex - RATE_D * p),
            iy * (TILT_P * ey - RATE_D * r_),
            -iz * YAW_RATE_D * yaw_rate,
        )
        weight = self.mass_kg * GRAVITY_M_S2
        thrust = max(self.mass_kg * norm * dz, MIN_THRUST_OF_WEIGHT * weight)
        forces = self._mix @ np.array([thrust, *torque])
        out = []
        for f in forces:
            omega = math.sqrt(max(0.0, float(f)) / self.k_f)
            out.append(min(1.0, omega / self.omega_max))
        return out


class GlideController:
    """A fixed wing's failsafe: throttle off, surfaces centred; None on the ground."""

    def command(self, state: VehicleState, hold_z_m: float | None = None) -> list[float] | None:
        if state.on_ground or state.crashed:
            return None
        return [0.0, 0.5, 0.5, 0.5]


def failsafe_controller(
    vtype: VehicleType, descend_speed_m_s: float
) -> LandController | GlideController:
    """The physics' failsafe for a vehicle type: Land for a multirotor, a glide for a plane."""
    if vtype.fixed_wing is not None:
        return GlideController()
    return LandController(vtype, descend_speed_m_s)


@dataclass(slots=True)
class Gap:
    """One vehicle's command outages."""

    first_tick: int = -1  # of the outage under way; -1: commanded
    hold_z_m: float = 0.0  # the altitude it holds at in the outage's first failsafe.hold_s
    ticks: int = 0  # in all
    outages: int = 0
    longest_ticks: int = 0


class CommandGaps:
    """Fills in the commands of the vehicles without one this tick (Hold, then Land, while
    airborne; motors off on the ground) and counts the ticks they went without."""

    def __init__(self, scenario: Scenario, vehicle_ids: Sequence[str]) -> None:
        self.control_dt_s = 1.0 / scenario.time.control_hz
        self.hold_ticks = {
            vid: round(scenario.failsafe_for(vid).hold_s * scenario.time.control_hz)
            for vid in vehicle_ids
        }
        self.controllers = {
            vid: failsafe_controller(
                load_vehicle_type(scenario.vehicle(vid).type),
                scenario.failsafe_for(vid).descend_speed_m_s,
            )
            for vid in vehicle_ids
        }
        self.gaps = {vid: Gap() for vid in vehicle_ids}

    def fill(
        self, tick: int, commands: Mapping[str, Sequence[float]], states: Sequence[VehicleState]
    ) -> dict[str, Sequence[float]]:
        """Tick ``tick``'s commands with the failsafe's for every vehicle missing from them
        (``states``: the tick's, in scenario order)."""
        out = dict(commands)
        for state in states:
            vid = state.vehicle_id
            gap = self.gaps[vid]
            if vid in commands:
                if gap.first_tick >= 0:
                    self._ended(vid, gap, tick)
                continue
            if gap.first_tick < 0:
                gap.first_tick = tick
                gap.hold_z_m = state.position_enu_m[2]
                gap.outages += 1
                log.warning(
                    "tick %d: no command from %s: %s",
                    tick,
                    vid,
                    "on the ground, motors off"
                    if state.on_ground
                    else f"the physics holds it {self.hold_ticks[vid] * self.control_dt_s:g} s, "
                    "then lands it (its failsafe)",
                )
            gap.ticks += 1
            holding = tick - gap.first_tick < self.hold_ticks[vid]
            rotor = self.controllers[vid].command(state, gap.hold_z_m if holding else None)
            if rotor is not None:
                out[vid] = rotor
        return out

    def _ended(self, vid: str, gap: Gap, tick: int) -> None:
        n = tick - gap.first_tick
        gap.longest_ticks = max(gap.longest_ticks, n)
        gap.first_tick = -1
        log.warning(
            "tick %d: %s commanded again after %d ticks without (%.2f s sim under the failsafe)",
            tick,
            vid,
            n,
            n * self.control_dt_s,
        )

    def note(self) -> str:
        """For the health detail: the vehicles that went without commands ("" if none)."""
        late = [(vid, g) for vid, g in self.gaps.items() if g.ticks]
        if not late:
            return ""
        parts = []
        for vid, g in late:
            now = " now" if g.first_tick >= 0 else ""
            parts.append(f"{vid} {g.ticks} in {g.outages}{now}")
        return "ticks without a command: " + ", ".join(parts)

    def summary(self, tick: int) -> str:
        """The run's last word on it: per vehicle, ticks without a command, outages, the
        longest (an outage under way counts up to ``tick``)."""
        lines = []
        for vid, g in self.gaps.items():
            if not g.ticks:
                continue
            longest = max(g.longest_ticks, tick - g.first_tick if g.first_tick >= 0 else 0)
            lines.append(
                f"{vid}: {g.ticks} ticks ({g.ticks * self.control_dt_s:.2f} s sim) in "
                f"{g.outages} outage(s), the longest {longest * self.control_dt_s:.2f} s"
            )
        if not lines:
            return "every vehicle commanded on every tick"
        return "ticks without a command (physics failsafe: hold, then land): " + "; ".join(lines)
