"""``plumeswarm bench scale`` runs tiny and writes its files (no speed assertions)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from agents import Swarm
from deploy.launcher import LaunchOptions, plan
from deploy.scaling import loop_mission, scale_scenario
from plumeswarm.bench.scale import CEILING, bench_scenario, command_into, markdown
from plumeswarm.experiments.driver import BusDriver, DriverError
from swarmbus.scenario import load_scenario, resolve_scenario_path
from tests.support.procs import NODE_COMMAND, run_cli, wait_until

COLUMNS = {
    "vehicles",
    "state",
    "real_time_factor",
    "ticks_per_s",
    "cpu_percent_by_role",
    "load1",
    "peak_rss_mb_by_role",
    "cpu_ms_per_tick_by_role",
}


def test_plan_packs_vehicles_per_process(tmp_path: Path) -> None:
    sc = scale_scenario(load_scenario(resolve_scenario_path(None)), 5)
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=tmp_path / "s.toml",
        roles=("autopilot",),
        vehicles_per_process=2,
    )
    specs = plan(sc, opts)
    assert [s.name for s in specs] == [
        "autopilot-uav1-plus1",
        "autopilot-uav3-plus1",
        "autopilot-uav5",
    ]
    assert specs[0].argv.count("--vehicle") == 2


def test_loop_mission_stays_in_the_air() -> None:
    sc = scale_scenario(load_scenario(resolve_scenario_path(None)), 3)
    items = loop_mission(sc, 1)
    assert items[0].command == "takeoff"
    assert all(i.command == "waypoint" for i in items[1:])
    assert len(items) <= 1000
    assert markdown([{"vehicles": 1, "state": "grounded", "error": "x"}]).count("\n") == 3


def test_bench_scale_tiny(tmp_path: Path) -> None:
    out = tmp_path / "scale"
    result = run_cli(
        [
            "bench",
            "scale",
            "--vehicles",
            "1,2",
            "--state",
            "grounded",
            "--seconds",
            "2",
            "--out",
            str(out),
        ],
        timeout_s=240.0,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    rows = json.loads((out / "scale.json").read_text())
    assert [(r["vehicles"], r["state"]) for r in rows] == [(1, "grounded"), (2, "grounded")]
    for row in rows:
        assert row.keys() >= COLUMNS
        roles = set(row["cpu_percent_by_role"])
        assert roles == {"physics", "autopilot", "plume", "gateway", "router"}
        assert row["ticks_per_s"] > 0
    table = (out / "scale.md").read_text()
    assert "| 2 | grounded |" in table
    assert (out / "rtf.png").stat().st_size > 0
    assert (out / "cpu.png").stat().st_size > 0


def test_the_ceiling_runs_the_same_processes_as_stand_ins(tmp_path: Path) -> None:
    sc = scale_scenario(load_scenario(resolve_scenario_path(None)), 4)
    real = plan(
        sc,
        LaunchOptions(
            node_command=NODE_COMMAND, scenario_path=tmp_path / "s.toml", vehicles_per_process=2
        ),
    )
    ceiling = plan(
        sc,
        LaunchOptions(
            node_command=NODE_COMMAND,
            scenario_path=tmp_path / "s.toml",
            vehicles_per_process=2,
            stand_ins=CEILING,
        ),
    )
    assert [(s.name, s.role) for s in ceiling] == [(s.name, s.role) for s in real]
    for spec in ceiling:
        node_role = spec.argv[spec.argv.index("node") + 1]
        if spec.role in CEILING:
            assert node_role == f"ceiling-{spec.role}"
            assert spec.argv[spec.argv.index("--name") + 1] == spec.name
        else:
            assert node_role == spec.role


def test_bench_scale_baseline_tiny(tmp_path: Path) -> None:
    out = tmp_path / "scale"
    result = run_cli(
        [
            *("bench", "scale", "--vehicles", "2", "--vehicles-per-process", "2"),
            *("--state", "hovering", "--seconds", "2", "--baseline", "--out", str(out)),
        ],
        timeout_s=240.0,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    (row,) = json.loads((out / "scale.json").read_text())
    assert row["ceiling_ticks_per_s"] > 0
    assert abs(row["fraction_of_ceiling"] - row["ticks_per_s"] / row["ceiling_ticks_per_s"]) < 2e-3
    assert "| 2 | hovering | 2 |" in (out / "scale.md").read_text()
    # the ceiling ran in its own run directory, with the stand-ins' logs in it
    assert (out / "ceiling-2").is_dir()


def test_the_benchs_driver_only_commands_and_its_commands_fly(tmp_path: Path) -> None:
    """The bench's path: a BusDriver with follow=False starts the stack, keeps no view of it and
    refuses to step; the hovering commands reach every autopilot: another client sees each
    vehicle climb above 5 m (it takes off to 10 m or more)."""
    sc = bench_scenario(load_scenario(resolve_scenario_path(None)), 2)
    ids = [v.id for v in sc.vehicles]
    driver = BusDriver(
        run_dir=tmp_path,
        mode="lockstep",
        roles=("router", "plume", "physics", "autopilot"),
        follow=False,
    )
    try:
        driver.start(sc)
        launcher = driver.launcher
        assert launcher is not None
        assert launcher.view is None
        with pytest.raises(DriverError, match="only commands"):
            driver.step(1)
        command_into(driver, sc, "hovering")
        with Swarm.connect(sc.world.name, launcher.scenario.network.connect) as sw:

            def climbed() -> bool:
                states = [sw.state(v) for v in ids]
                return all(s is not None and s.position_enu_m[2] > 5.0 for s in states)

            wait_until(climbed, 60.0, "both vehicles above 5 m")
    finally:
        driver.close()
