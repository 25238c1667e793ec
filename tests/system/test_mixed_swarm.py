"""A mixed swarm on the real distributed stack: ``plumeswarm up mixed --headless --stepped``
(router, plume, physics and one autopilot process per vehicle, on loopback) flies the bundled
``mixed`` scenario — three Iris quadcopters and one Aerosonde plane in the default scenario's
plume and mission pattern — from the ground to every vehicle disarmed.

Measured against the scenario file (read with ``tomllib``) and the plume's closed form, never
against the autopilot's or the plume service's own numbers: every vehicle takes off, passes its
waypoints in order, lands and disarms (the plane stops within ``PLANE_STOP_WITHIN_M`` of its
landing point, touching down within ``PLANE_TOUCHDOWN_WITHIN_M``, never sinking onto the ground
faster than the scenario's crash speed); every reading any vehicle published is at that
vehicle's position at the reading's tick, as the physics published it, and its true value is
the Gaussian plume's closed form there (its reported value the sensor window of it)."""

from __future__ import annotations

import math
import threading
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from agents import ClockError, Swarm
from plume_atmosphere.dispersion import dispersion_curves
from swarmbus.messages import ConcentrationReading, VehicleState, VehicleStatus
from swarmbus.scenario import SCENARIOS_DIR
from swarmbus.vehicle_types import load_vehicle_type
from tests.support.procs import wait_until
from tests.support.upstack import plumeswarm_up

RAW = tomllib.loads((SCENARIOS_DIR / "mixed.toml").read_text())
VEHICLES: dict[str, dict[str, Any]] = {v["id"]: v for v in RAW["vehicles"]}
PLANES = [vid for vid, v in VEHICLES.items() if load_vehicle_type(v["type"]).kind == "fixed_wing"]
ROLES = "router,plume,physics,autopilot"
CONTROL_HZ = RAW["time"]["control_hz"]
SENSOR_PERIOD = RAW["sensor"]["period_ticks"]
CRASH_SPEED_M_S = 3.0  # the schema's default: the scenario's [failsafe] leaves it
STEP_TICKS = 120  # the test steps the clock one sim second at a time
FLIGHT_TIMEOUT_S = 120.0  # sim time: the multirotors need ≈ 33 s, the plane ≈ 58 s
# The plane: first ground contact within this of its landing point (the flare floats it past),
# stopped within this of it (Bullet's friction slides it on), on the approach line.
PLANE_TOUCHDOWN_WITHIN_M = 50.0
PLANE_STOP_WITHIN_M = 100.0
PLANE_OFF_LINE_M = 10.0
MULTIROTOR_LAND_WITHIN_M = 0.5

# novak2018's plume (docs/plume.md): class D with the seed's coefficients, Q 10 g/s, release
# height 10 m, the wind 6 m/s from the west (toward +x), source at the origin; the sensor's
# window [0.01, 0.2] g/m3.
Q_G_S, U_M_S, H_M = 10.0, 6.0, 10.0
DETECTION_G_M3, SATURATION_G_M3 = 0.01, 0.2
CURVES = dispersion_curves("novak2018", "D")


def closed_form_g_m3(points: np.ndarray) -> np.ndarray:
    """The Gaussian plume with its ground image at (N, 3) ENU points (x downwind)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    sy, sz = CURVES.sigmas(x)
    vertical = np.exp(-0.5 * ((z - H_M) / sz) ** 2) + np.exp(-0.5 * ((z + H_M) / sz) ** 2)
    return np.asarray(
        Q_G_S / (2 * math.pi * U_M_S * sy * sz) * np.exp(-0.5 * (y / sy) ** 2) * vertical
    )


@dataclass
class Flight:
    """What the test's own subscription saw (Zenoh's threads), under ``lock``."""

    lock: threading.Lock = field(default_factory=threading.Lock)
    states: dict[tuple[str, int], VehicleState] = field(default_factory=dict)
    readings: list[ConcentrationReading] = field(default_factory=list)
    statuses: dict[str, VehicleStatus] = field(default_factory=dict)

    def on_state(self, state: VehicleState) -> None:
        with self.lock:
            self.states[(state.vehicle_id, state.tick)] = state

    def on_reading(self, reading: ConcentrationReading) -> None:
        with self.lock:
            self.readings.append(reading)

    def on_status(self, status: VehicleStatus) -> None:
        with self.lock:
            self.statuses[status.vehicle_id] = status

    def track(self, vid: str) -> list[VehicleState]:
        with self.lock:
            return [s for (v, _), s in sorted(self.states.items()) if v == vid]


def _sim_time(sw: Swarm) -> float | None:
    try:
        return sw.sim_time + 1.0  # truthy at t = 0 too
    except ClockError:
        return None


@pytest.fixture(scope="module")
def flight(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Flight]:
    tmp = tmp_path_factory.mktemp("mixed")
    seen = Flight()
    # the bundled scenario by its name, as a user starts it
    with (
        plumeswarm_up(Path("mixed"), tmp, "--headless", "--stepped", "--roles", ROLES) as up,
        Swarm.connect(connect=[up.endpoint], command_timeout_s=20.0) as sw,
    ):
        sub = sw.subscribe(
            on_state=seen.on_state, on_status=seen.on_status, on_reading=seen.on_reading
        )
        wait_until(lambda: _sim_time(sw), 120.0, "the stepped world's clock")
        sw.step(1)
        for vid in VEHICLES:  # each autopilot holds its scenario mission
            sw.command(vid).arm()
            sw.command(vid).start_mission()

        def done() -> bool:
            with seen.lock:
                st = dict(seen.statuses)
            return all(
                (s := st.get(v)) is not None and s.mission_finished and not s.armed
                for v in VEHICLES
            )

        sw.step_until(done, FLIGHT_TIMEOUT_S, "every vehicle landed and disarmed", STEP_TICKS)
        sub.close()
    yield seen


def test_the_scenario_is_three_multirotors_and_one_plane() -> None:
    kinds = sorted(load_vehicle_type(v["type"]).kind for v in VEHICLES.values())
    assert kinds == ["fixed_wing", "multirotor", "multirotor", "multirotor"]


def test_every_vehicle_takes_off_flies_its_pattern_lands_and_disarms(flight: Flight) -> None:
    for vid, spec in VEHICLES.items():
        track = flight.track(vid)
        ticks = [s.tick for s in track]
        assert ticks == list(range(ticks[0], ticks[-1] + 1)), f"{vid}: states missing"
        assert not any(s.crashed for s in track), vid
        status = flight.statuses[vid]
        assert status.mission_finished and status.landed and not status.armed, vid
        assert status.mission_items_reached == len(spec["mission"]), vid
        takeoff, *waypoints, land = spec["mission"]
        assert takeoff["command"] == "takeoff" and land["command"] == "land"
        assert max(s.position_enu_m[2] for s in track) > takeoff["z"] - 2.0, f"{vid} never rose"
        plane = vid in PLANES
        # the waypoints, in order: the first tick within reach of each comes after the last's
        reach = _turn_radius_m(spec["type"]) if plane else waypoints[0]["acceptance_radius_m"]
        at = 0
        for wp in waypoints:
            near = [
                i
                for i in range(at, len(track))
                if math.dist(track[i].position_enu_m[:2], (wp["x"], wp["y"])) <= reach
            ]
            assert near, f"{vid} never within {reach:.1f} m of waypoint {wp}"
            at = near[0]
        end = track[-1]
        assert end.on_ground and math.hypot(*end.velocity_enu_m_s[:2]) < 1.0, vid
        gone = math.dist(end.position_enu_m[:2], (land["x"], land["y"]))
        if plane:
            _plane_landed(vid, track, waypoints[-1], land)
        else:
            assert gone <= MULTIROTOR_LAND_WITHIN_M, f"{vid} landed {gone:.2f} m off its point"


def _turn_radius_m(vehicle_type: str) -> float:
    """The plane's tightest level turn at its trim airspeed: V² / (g tan FW_R_LIM)."""
    fw = load_vehicle_type(vehicle_type).fixed_wing
    assert fw is not None
    p = fw.params
    return p.fw_airspd_trim**2 / (9.80665 * math.tan(math.radians(p.fw_r_lim)))


def _plane_landed(
    vid: str, track: list[VehicleState], last: dict[str, Any], land: dict[str, Any]
) -> None:
    """Touchdown and stop near the landing point, on the approach line (from the last
    waypoint through the point), never sinking onto the ground faster than the crash speed."""
    airborne = next(i for i, s in enumerate(track) if s.position_enu_m[2] > 5.0)
    contacts = [
        i for i in range(airborne, len(track)) if track[i].on_ground and not track[i - 1].on_ground
    ]
    assert contacts, f"{vid} never came down"
    for i in contacts:  # the sink rate at each new ground contact, 0.5 s before included
        sink = max(-s.velocity_enu_m_s[2] for s in track[max(0, i - CONTROL_HZ // 2) : i + 1])
        assert sink < CRASH_SPEED_M_S, f"{vid} hit the ground sinking {sink:.2f} m/s"
    point = (land["x"], land["y"])
    touchdown = math.dist(track[contacts[0]].position_enu_m[:2], point)
    assert touchdown <= PLANE_TOUCHDOWN_WITHIN_M, f"{vid} touched down {touchdown:.1f} m off"
    stop = track[-1].position_enu_m
    assert math.dist(stop[:2], point) <= PLANE_STOP_WITHIN_M, f"{vid} stopped at {stop}"
    ux, uy = land["x"] - last["x"], land["y"] - last["y"]
    n = math.hypot(ux, uy)
    off = abs(ux * (stop[1] - land["y"]) - uy * (stop[0] - land["x"])) / n
    assert off <= PLANE_OFF_LINE_M, f"{vid} stopped {off:.1f} m off the approach line"


def test_every_reading_is_the_plume_model_at_the_vehicle_s_position(flight: Flight) -> None:
    with flight.lock:
        readings = list(flight.readings)
        states = dict(flight.states)
    assert {r.vehicle_id for r in readings} == set(VEHICLES)
    for vid in VEHICLES:
        # a reading every sensor period (10 Hz) of at least 25 s of flight
        n = sum(1 for r in readings if r.vehicle_id == vid)
        assert n >= 25 * CONTROL_HZ / SENSOR_PERIOD, (vid, n)
    positions = []
    for r in readings:
        assert r.available, r
        tick = round(r.sim_time_s * CONTROL_HZ)
        assert tick % SENSOR_PERIOD == 0, r
        state = states.get((r.vehicle_id, tick))
        if state is None:  # tick 0 was published before the test's client joined
            assert tick == 0, f"no state of {r.vehicle_id} at tick {tick}"
            spawn = VEHICLES[r.vehicle_id]["spawn_enu_m"]
            assert math.dist(r.position_enu_m, spawn) < 0.2, r  # at rest on its spawn point
        else:
            assert state.sim_time_s == pytest.approx(r.sim_time_s, abs=1e-9)
            assert r.position_enu_m == state.position_enu_m, (r, state)
        positions.append(r.position_enu_m)
    truth = closed_form_g_m3(np.array(positions, dtype=np.float64))
    true = np.array([r.true_g_m3 for r in readings], dtype=np.float64)
    np.testing.assert_allclose(true, truth, rtol=1e-9, atol=0)
    window = np.where(truth < DETECTION_G_M3, 0.0, np.minimum(truth, SATURATION_G_M3))
    reported = np.array([r.reported_g_m3 for r in readings], dtype=np.float64)
    np.testing.assert_allclose(reported, window, rtol=1e-9, atol=0)
    # the test can tell: the multirotors cross the sensor's window, the plane reads the plume
    # far downwind, below the detection limit but not zero
    inside = (window > 0.0) & (window < SATURATION_G_M3)
    assert inside.sum() > 100
    plane = np.array([r.vehicle_id in PLANES for r in readings])
    airborne = np.array([p[2] > 5.0 for p in positions])
    # on the plume's axis 200-440 m downwind at 10 m the model gives up to ≈ 3·10⁻⁴ g/m3
    assert truth[plane & airborne].max() > 1e-4
