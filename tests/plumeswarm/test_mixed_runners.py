"""The bundled ``mixed`` scenario (three Iris, one Aerosonde) in each runner that takes a
scenario: the fused runner flies it to the end; the demo scales it down but not up; the
runners that fly every vehicle as a multirotor (the environments, ``bench scale``) and
``chaos`` (a plane's autopilot does not resume bit for bit) refuse it in one line naming the
plane and the valid vehicle types. The distributed stack's flight is
tests/system/test_mixed_swarm.py."""

from __future__ import annotations

import math

import pytest

from deploy.scaling import ScalingError, fixed_wing_vehicles, scale_scenario
from plumeswarm.envs import PlumeSwarmEnv
from plumeswarm.experiments.fused import FusedRunner
from swarmbus.messages import Arm, MissionStart
from swarmbus.scenario import load_scenario, resolve_scenario_path
from tests.support.procs import run_cli

MIXED = load_scenario(resolve_scenario_path("mixed"))


def test_the_mixed_scenario_has_one_plane() -> None:
    assert fixed_wing_vehicles(MIXED) == ["plane"]
    assert fixed_wing_vehicles(load_scenario()) == []


def test_the_fused_runner_flies_every_vehicle_to_the_ground() -> None:
    with FusedRunner(MIXED) as run:
        for v in MIXED.vehicles:
            assert run.command(v.id, Arm()).accepted
            assert run.command(v.id, MissionStart()).accepted
        kinds = {vid: f.autopilot.kind for vid, f in run.flights.items()}
        assert kinds == {"uav1": "multirotor", "uav2": "multirotor", "uav3": "multirotor",
                         "plane": "fixed_wing"}  # fmt: skip
        highest = dict.fromkeys(kinds, 0.0)
        for _ in range(90 * 120):  # 90 s of sim time at most; the plane needs ≈ 55 s
            states = run.step(1)
            for s in states:
                assert not s.crashed, s
                highest[s.vehicle_id] = max(highest[s.vehicle_id], s.position_enu_m[2])
            status = [run.flights[v].autopilot.status() for v in kinds]
            if all(st.mission_finished and not st.armed for st in status):
                break
        assert all(st.mission_finished and st.landed and not st.armed for st in status)
        assert all(h > 8.0 for h in highest.values()), highest
        assert all(s.on_ground for s in states)


def _yaw_deg(q: tuple[float, float, float, float]) -> float:
    x, y, z, w = q
    return math.degrees(math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)))


def test_the_plane_waits_on_its_runway_facing_the_wind() -> None:
    """Disarmed for a minute in the scenario's 6 m/s west wind, the plane keeps its spawn pose
    (into the wind), so its runway take-off goes up the plume's axis whenever it is armed."""
    spec = MIXED.vehicle("plane")
    into_wind_enu_deg = (90.0 - MIXED.wind.from_deg) % 360.0  # compass "from" → ENU yaw
    assert spec.spawn_yaw_deg == pytest.approx(into_wind_enu_deg)
    with FusedRunner(MIXED) as run:
        for _ in range(60):
            plane = next(s for s in run.step(120) if s.vehicle_id == "plane")
            turned = (_yaw_deg(plane.attitude_xyzw) - spec.spawn_yaw_deg + 180.0) % 360.0 - 180.0
            assert abs(turned) < 1.0, (plane.sim_time_s, turned)
            assert math.dist(plane.position_enu_m[:2], spec.spawn_enu_m[:2]) < 0.1, plane


def test_scaling_goes_down_but_not_up() -> None:
    two = scale_scenario(MIXED, 2)
    assert [v.id for v in two.vehicles] == ["uav1", "uav2"]
    with pytest.raises(
        ScalingError, match=r"--vehicles 5: vehicle 'plane' is a fixed wing.*1\.\.4"
    ):
        scale_scenario(MIXED, 5)


def test_the_environments_refuse_a_plane() -> None:
    with pytest.raises(ValueError, match=r"vehicle 'plane' is a fixed wing .*iris, typhoon_h480"):
        PlumeSwarmEnv("mixed")


@pytest.mark.parametrize(
    "args",
    [
        ["demo", "--scenario", "mixed", "--vehicles", "6"],
        ["chaos", "mixed"],
        ["bench", "scale", "--scenario", "mixed", "--vehicles", "1"],
    ],
)
def test_a_runner_that_cannot_fly_it_says_so_in_one_line(args: list[str]) -> None:
    r = run_cli(args, timeout_s=60.0)
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("plumeswarm: error:"), r.stderr
    assert "vehicle 'plane' is a fixed wing" in lines[0] and "Traceback" not in r.stderr
