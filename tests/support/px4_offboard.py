"""PX4 workflows in the air through MAVSDK's plugins, from a hover after take-off: offboard
setpoints of every kind, orbit, position mode with sticks and follow-me; each asserts what the
vehicle did (tests/gcs_bridge/test_gateway_px4.py flies them). Imports MAVSDK: a test imports
this only after ``pytest.importorskip("mavsdk")``."""

from __future__ import annotations

import asyncio
import math
from typing import Any

from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.follow_me import FollowMeAsync
from mavsdk.asyncio.plugins.manual_control import ManualControlAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.action import OrbitYawBehavior
from mavsdk.plugins.follow_me import Config as FollowConfig
from mavsdk.plugins.follow_me import TargetLocation
from mavsdk.plugins.offboard import (
    AccelerationNed,
    Attitude,
    AttitudeRate,
    PositionGlobalYaw,
    PositionNedYaw,
    VelocityBodyYawspeed,
    VelocityNedYaw,
)

from swarmbus.vehicle_types import load_vehicle_type
from tests.support.mavclient import first
from tests.support.px4_flight import (
    ORIGIN,
    SPAWN_ENU,
    arrive,
    east_north_of,
    latlon,
    moved,
    take_off,
)


async def orbit_clockwise(system: Any, east: float, north: float) -> None:
    tel, act = TelemetryAsync(system), ActionAsync(system)
    here = await first(tel.subscribe_position(), lambda p: True, "a position")
    lat, lon = latlon(east, north)
    await act.do_orbit(
        8.0, 2.0, OrbitYawBehavior.HOLD_FRONT_TO_CIRCLE_CENTER, lat, lon, here.absolute_altitude_m
    )

    def radius(p: Any) -> float:
        return math.dist(east_north_of(p), (east, north))

    await first(tel.subscribe_position(), lambda p: abs(radius(p) - 8.0) < 0.7, "on the circle")
    start = east_north_of(await first(tel.subscribe_position(), lambda p: True, "a position"))
    a0 = math.atan2(start[1] - north, start[0] - east)

    def swept(p: Any) -> float:
        e, n = east_north_of(p)
        return (math.atan2(n - north, e - east) - a0 + math.pi) % (2 * math.pi) - math.pi

    # clockwise seen from above: the bearing from the centre decreases (ENU)
    await first(
        tel.subscribe_position(),
        lambda p: -1.5 < swept(p) < -1.0 and abs(radius(p) - 8.0) < 1.0,
        "a quarter turn clockwise on the circle",
        60.0,
    )


async def position_mode_with_sticks(system: Any) -> None:
    tel, manual = TelemetryAsync(system), ManualControlAsync(system)
    sticks = [0.0, 0.0, 0.5, 0.0]  # x forward, y right, z throttle (0.5: hold), r yaw

    async def joystick() -> None:  # a ground station sends its sticks continuously
        while True:
            await manual.set_manual_control_input(*sticks)
            await asyncio.sleep(0.02)

    stream = asyncio.create_task(joystick())
    try:
        await asyncio.sleep(0.2)
        await manual.start_position_control()
        await first(tel.subscribe_flight_mode(), lambda m: m.name == "POSCTL", "POSCTL")
        heading = (await first(tel.subscribe_heading(), lambda h: True, "a heading")).heading_deg
        sticks[0] = 0.4
        east, north = await moved(tel, 5.0, "forward stick")
        nose = (math.sin(math.radians(heading)), math.cos(math.radians(heading)))
        assert east * nose[0] + north * nose[1] > 0.9, f"flew ({east:.2f}, {north:.2f})"
        sticks[0] = 0.0
        await first(
            tel.subscribe_velocity_ned(),
            lambda v: math.hypot(v.north_m_s, v.east_m_s) < 0.3,
            "a stop with centred sticks",
        )
    finally:
        stream.cancel()


async def follow_a_walking_target(system: Any) -> None:
    tel, follow = TelemetryAsync(system), FollowMeAsync(system)
    await follow.set_config(FollowConfig(follow_height_m=9.0, follow_distance_m=6.0))
    here = east_north_of(await first(tel.subscribe_position(), lambda p: True, "a position"))
    walk = {"north": here[1] + 10.0}

    async def target() -> None:  # someone walking north at 1.5 m/s (wall clock), 1 Hz fixes
        while True:
            lat, lon = latlon(here[0], walk["north"])
            await follow.set_target_location(TargetLocation(lat, lon, ORIGIN.alt_m, 1.5, 0.0, 0.0))
            await asyncio.sleep(0.2)
            walk["north"] += 0.3

    walker = asyncio.create_task(target())
    try:
        await follow.start()
        await first(tel.subscribe_flight_mode(), lambda m: m.name == "FOLLOW_ME", "FOLLOW_ME")

        def behind(p: Any) -> bool:
            e, n = east_north_of(p)
            return (
                abs(e - here[0]) < 1.5
                and abs(n - (walk["north"] - 6.0)) < 2.5
                and abs(p.relative_altitude_m - 9.0) < 1.0
            )

        await first(tel.subscribe_position(), behind, "6 m behind the walker at 9 m", 60.0)
        await follow.stop()
    finally:
        walker.cancel()


IRIS = load_vehicle_type("iris")
HOVER_THRUST = IRIS.mass_kg * 9.80665 / IRIS.max_total_thrust_n  # fraction of the maximum


async def hold_here(off: Any, tel: Any, before: str) -> tuple[float, float]:
    """Hold the position, nose north, 6 m up, until stopped; where (east, north) it held."""
    e0, n0 = SPAWN_ENU
    here = east_north_of(await first(tel.subscribe_position(), lambda p: True, "a position"))
    await off.set_position_ned(PositionNedYaw(here[1] - n0, here[0] - e0, -6.0, 0.0))
    await first(
        tel.subscribe_velocity_ned(),
        lambda v: math.hypot(v.north_m_s, v.east_m_s) < 0.2,
        f"a stop before {before}",
    )
    return here


async def turned_deg(tel: Any, beyond_deg: float, what: str) -> float:
    """The heading's change (degrees, clockwise positive) once it is more than ``beyond_deg``
    either way; followed sample by sample so that a turn past 180 degrees stays a turn."""
    stream = tel.subscribe_heading()
    try:
        last = (await first(stream, lambda h: True, "a heading")).heading_deg
        total = 0.0

        def far(h: Any) -> bool:
            nonlocal last, total
            total += (h.heading_deg - last + 180.0) % 360.0 - 180.0
            last = h.heading_deg
            return abs(total) > beyond_deg

        await first(stream, far, what, 60.0)
        return total
    finally:
        await stream.aclose()


async def flown_straight(
    off: Any, tel: Any, offset: tuple[float, float], accel_m_s2: float | None
) -> None:
    """From a hover, a position ``offset`` (east, north) metres away with a 1.5 m/s velocity
    feed-forward towards it (and an ``accel_m_s2`` one): flown along the line to it."""
    e0, n0 = SPAWN_ENU
    kind = "position-velocity" if accel_m_s2 is None else "position-velocity-acceleration"
    what = f"the {kind} setpoint"
    here = await hold_here(off, tel, what)
    goal = (here[0] + offset[0], here[1] + offset[1])
    d = math.hypot(*offset)
    east_u, north_u = offset[0] / d, offset[1] / d
    position = PositionNedYaw(goal[1] - n0, goal[0] - e0, -6.0, 0.0)
    velocity = VelocityNedYaw(1.5 * north_u, 1.5 * east_u, 0.0, 0.0)
    if accel_m_s2 is None:
        await off.set_position_velocity_ned(position, velocity)
    else:
        acceleration = AccelerationNed(accel_m_s2 * north_u, accel_m_s2 * east_u, 0.0)
        await off.set_position_velocity_acceleration_ned(position, velocity, acceleration)
    east, north = await moved(tel, d / 2.0, what)
    cos = east * east_u + north * north_u
    assert cos > 0.95, f"towards ({east_u:.2f}, {north_u:.2f}) flew ({east:.2f}, {north:.2f})"
    await arrive(tel, *goal, what)


async def offboard_ned_setpoints_as_px4(off: Any, tel: Any) -> None:
    """NED velocity, position with velocity (and acceleration) feed-forward, acceleration and
    body rates, each from a hover, nose north."""
    # velocity north-west at 2.5 m/s: the velocity loop flies the direction, wind or not
    await hold_here(off, tel, "the NED velocity setpoint")
    await off.set_velocity_ned(VelocityNedYaw(1.5, -2.0, 0.0, 0.0))
    east, north = await moved(tel, 5.0, "the NED velocity setpoint")
    cos = (east * -2.0 + north * 1.5) / 2.5
    assert cos > 0.95, f"velocity NED (1.5, -2.0) flew ({east:.2f}, {north:.2f})"
    # a position with a velocity feed-forward, then one with an acceleration feed-forward too
    await flown_straight(off, tel, (7.0, -4.0), None)
    await flown_straight(off, tel, (-7.0, 4.0), 0.3)
    # 3 m/s² west, into the 6 m/s west wind (its drag, ≈ 1 m/s² at rest, is along the same
    # axis): PX4 takes an acceleration alone as feed-forward, so the speed builds westward
    await hold_here(off, tel, "the acceleration setpoint")
    await off.set_acceleration_ned(AccelerationNed(0.0, -3.0, 0.0))
    v = await first(
        tel.subscribe_velocity_ned(),
        lambda v: math.hypot(v.north_m_s, v.east_m_s) > 2.5,
        "2.5 m/s from the acceleration setpoint",
        60.0,
    )
    cos = -v.east_m_s / math.hypot(v.north_m_s, v.east_m_s)
    assert cos > 0.95, f"3 m/s² west built ({v.north_m_s:.2f}, {v.east_m_s:.2f}) m/s NE"
    # body rates: yaw −45 °/s (counter-clockwise seen from above), no roll or pitch, hover thrust
    await hold_here(off, tel, "the attitude-rate setpoint")
    await off.set_attitude_rate(AttitudeRate(0.0, 0.0, -45.0, HOVER_THRUST))
    turn = await turned_deg(tel, 60.0, "a 60 degree turn from the yaw rate")
    assert turn < 0.0, f"yaw rate −45 °/s turned the heading {turn:+.0f} degrees"
    await hold_here(off, tel, "the end of offboard")


async def offboard_setpoints_as_px4(system: Any) -> None:
    tel, act, param = TelemetryAsync(system), ActionAsync(system), ParamAsync(system)
    off = OffboardAsync(system)
    # the simulation runs faster than real time: MAVSDK's 20 Hz stream must not look lost
    await param.set_param_float("COM_OF_LOSS_T", 30.0)
    await take_off(system, 5.0)
    e0, n0 = SPAWN_ENU
    # local NED from the vehicle's own origin: 5 m north of its spawn, nose east (NED yaw 90)
    await off.set_position_ned(PositionNedYaw(5.0, 0.0, -6.0, 90.0))
    await off.start()
    await arrive(tel, e0, n0 + 5.0, "local NED (5, 0) from the spawn")
    await first(tel.subscribe_heading(), lambda h: abs(h.heading_deg - 90.0) < 5.0, "nose east")
    await off.set_velocity_body(VelocityBodyYawspeed(2.0, 0.0, 0.0, 0.0))
    east, north = await moved(tel, 5.0, "body-frame forward flight")
    assert east > 0.95, f"body forward with the nose east flew ({east:.2f}, {north:.2f})"
    # attitude from rest, nose north: 20 degrees nose down, thrust to hold the altitude; the
    # tilt (g·tan 20° ≈ 3.6 m/s²) outweighs the drag of the 6 m/s west wind
    await hold_here(off, tel, "the attitude setpoint")
    await first(
        tel.subscribe_heading(),
        lambda h: min(h.heading_deg % 360.0, 360.0 - h.heading_deg % 360.0) < 5.0,
        "nose north",
    )
    await off.set_attitude(Attitude(0.0, -20.0, 0.0, HOVER_THRUST / math.cos(math.radians(20.0))))
    east, north = await moved(tel, 4.0, "the attitude setpoint's acceleration")
    assert north > 0.8, f"nose down heading north flew ({east:.2f}, {north:.2f})"
    lat, lon = latlon(e0 - 5.0, n0 + 10.0)
    await off.set_position_global(
        PositionGlobalYaw(lat, lon, 6.0, 0.0, PositionGlobalYaw.AltitudeType.REL_HOME)
    )
    await arrive(tel, e0 - 5.0, n0 + 10.0, "the global setpoint", within_m=1.5)
    await offboard_ned_setpoints_as_px4(off, tel)
    await off.stop()
    await orbit_clockwise(system, e0 + 3.0, n0 + 10.0)
    await position_mode_with_sticks(system)
    await follow_a_walking_target(system)
    await act.land()
    await first(tel.subscribe_armed(), lambda armed: not armed, "landed and disarmed", 180.0)
