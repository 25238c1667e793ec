"""The Gymnasium and PettingZoo environments: the standard conformance checks, repeatability,
the default reward against the geometry, and the bus backend against the fused one."""

from __future__ import annotations

import gc
import json
import math
import os
import socket
import subprocess
import sys
from pathlib import Path
from typing import Any

import gymnasium
import msgspec
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test

from deploy.launcher import Launcher, LaunchOptions
from deploy.scaling import write_scenario
from plume_atmosphere.wind import wind_from_scenario
from plumeswarm.envs import ENV_ID, AgentStep, PlumeSourceEnv, PlumeSwarmEnv
from swarmbus.scenario import ScenarioError, WindMeander, load_scenario, parse_scenario
from swarmbus.session import free_tcp_port
from tests.support.browser import CHROMIUM, chromium_page, wait_for_scene_nodes
from tests.support.procs import NODE_COMMAND, REPO, run_cli


def scripted_actions(seed: int, agents: list[str], steps: int) -> list[dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return [{a: rng.uniform(-1.0, 1.0, 4).astype(np.float32) for a in agents} for _ in range(steps)]


def trajectory(env: PlumeSwarmEnv, seed: int, steps: int) -> list[dict[str, np.ndarray]]:
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for actions in scripted_actions(seed, env.possible_agents, steps):
        obs, *_ = env.step(actions)
        out.append(obs)
    return out


def assert_same(a: list[dict[str, np.ndarray]], b: list[dict[str, np.ndarray]]) -> None:
    assert len(a) == len(b)
    for step, (x, y) in enumerate(zip(a, b, strict=True)):
        assert x.keys() == y.keys(), step
        for agent in x:
            assert np.array_equal(x[agent], y[agent]), (step, agent, x[agent], y[agent])


def test_source_env_is_registered_and_passes_check_env() -> None:
    env = gymnasium.make(ENV_ID)
    try:
        check_env(env.unwrapped)
    finally:
        env.close()


def test_swarm_env_passes_the_parallel_api_test() -> None:
    env = PlumeSwarmEnv()
    try:
        parallel_api_test(env, num_cycles=30)
    finally:
        env.close()


def test_reset_with_a_seed_repeats_the_trajectory_and_another_seed_does_not() -> None:
    env = PlumeSwarmEnv(vehicles=4)
    try:
        first = trajectory(env, 11, 15)
        second = trajectory(env, 11, 15)
        other = trajectory(env, 12, 15)
    finally:
        env.close()
    assert_same(first, second)
    assert not np.array_equal(first[0]["uav1"], other[0]["uav1"])


def test_start_lies_in_the_box_in_offboard_at_the_drawn_altitude() -> None:
    env = PlumeSwarmEnv()
    try:
        obs, _ = env.reset(seed=5)
        box = env.scenario.env
        for agent, o in obs.items():
            x, y, z = o[:3]
            assert box.start_min_enu_m[0] <= x <= box.start_max_enu_m[0], agent
            assert box.start_min_enu_m[1] <= y <= box.start_max_enu_m[1], agent
            # the take-off altitude above the ground (the body's centre sits ~6 cm up)
            assert box.start_min_enu_m[2] - 0.5 <= z <= box.start_max_enu_m[2] + 0.6, agent
        runner = env.backend.runner  # type: ignore[attr-defined]
        modes = {f.autopilot.modes.mode for f in runner.flights.values()}
        assert modes == {"offboard"}
    finally:
        env.close()


def test_flying_at_the_source_earns_the_distance_closed() -> None:
    """The default reward is metres of progress: flying straight at the source for T seconds
    closes at most v·T metres and, with the autopilot tracking the setpoint, most of that."""
    env = PlumeSourceEnv()
    try:
        obs, info = env.reset(seed=2)
        source = np.array([0.0, 0.0, 10.0])  # the default scenario's release point
        start = info["distance_m"]
        assert start == pytest.approx(float(np.linalg.norm(obs[:3] - source)), rel=1e-5)
        total = 0.0
        steps = 30  # 3 s at 10 steps/s
        for _ in range(steps):
            direction = (source - obs[:3]) / np.linalg.norm(source - obs[:3])
            action = np.append(direction, 0.0).astype(np.float32)
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            assert not (terminated or truncated)
        assert total == pytest.approx(start - info["distance_m"], abs=1e-9)
        assert 0.5 * 5.0 * 3.0 < total <= math.hypot(5.0, 2.0) * 3.0
    finally:
        env.close()


def test_termination_and_reward_are_pluggable() -> None:
    seen: list[AgentStep] = []

    def reward(step: AgentStep) -> float:
        seen.append(step)
        return -1.0

    env = PlumeSwarmEnv(reward_fn=reward, termination_fn=lambda s: (s.elapsed_s >= 0.25, False))
    try:
        env.reset(seed=1)
        zero = {a: np.zeros(4, dtype=np.float32) for a in env.agents}
        _, rewards, terminated, _, _ = env.step(zero)
        assert set(rewards.values()) == {-1.0} and not any(terminated.values())
        _, _, terminated, _, _ = env.step(zero)  # 2 × 0.1 s
        _, _, terminated, _, _ = env.step(zero)
        assert all(terminated.values()) and env.agents == []
        assert len(seen) == 9 and {s.vehicle_id for s in seen} == set(env.possible_agents)
    finally:
        env.close()


def test_rgb_array_is_a_top_down_frame_with_the_vehicles() -> None:
    env = PlumeSwarmEnv(render_mode="rgb_array")
    try:
        env.reset(seed=3)
        frame = env.render()
    finally:
        env.close()
    assert isinstance(frame, np.ndarray) and frame.dtype == np.uint8 and frame.shape[2] == 3
    assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 50  # a plume, axes, vehicles


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"backend": "carrier-pigeon"}, "backend"),
        ({"ticks_per_step": 120}, "ticks_per_step"),
        ({"ticks_per_step": 0}, "ticks_per_step"),
        ({"k_peers": -1}, "k_peers"),
        ({"render_mode": "ansi"}, "render_mode"),
    ],
)
def test_bad_arguments_name_the_field(kwargs: dict[str, object], field: str) -> None:
    with pytest.raises(ValueError, match=field):
        PlumeSwarmEnv(**kwargs)  # type: ignore[arg-type]


def test_bus_backend_gives_the_fused_backends_observations() -> None:
    fused = PlumeSwarmEnv()
    bus = PlumeSwarmEnv(backend="bus")
    try:
        expected = trajectory(fused, 21, 10)
        got = trajectory(bus, 21, 10)
    finally:
        fused.close()
        bus.close()
    assert_same(expected, got)


def test_the_scripted_policy_of_the_docs_runs_and_finds_the_source() -> None:
    text = (REPO / "docs" / "envs.md").read_text()
    section = text.split("## A scripted policy", 1)[1]
    code = section.split("```python\n", 1)[1].split("```", 1)[0]
    env = dict(os.environ, PYTHONPATH=str(REPO))
    res = subprocess.run(
        [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True, timeout=240
    )
    assert res.returncode == 0, res.stderr[-2000:]
    printed = res.stdout.strip().splitlines()[-1]
    assert printed.startswith("found the source at t = "), printed
    assert printed in text  # the docs quote what it prints


def bench_envs(out: Path, backends: str, vehicles: str, steps: int) -> tuple[str, list[Any]]:
    """``plumeswarm bench envs``'s output and rows."""
    res = run_cli(
        ["bench", "envs", "--backends", backends, "--vehicles", vehicles, "--steps", str(steps),
         "--out", str(out)],
        timeout_s=240,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr[-2000:]
    rows: list[Any] = json.loads((out / "envs.json").read_text())
    return res.stdout, rows


def test_bench_envs_writes_one_row_per_backend_and_count(tmp_path: Path) -> None:
    stdout, rows = bench_envs(tmp_path, "fused", "1,2", 3)
    assert [(r["backend"], r["vehicles"]) for r in rows] == [("fused", 1), ("fused", 2)]
    for row in rows:
        assert row["steps"] == 3 and row["steps_per_s"] > 0
        # 3 steps of 12 ticks at 120 Hz: 0.3 s of sim time over the measured wall time
        assert row["real_time_factor"] == pytest.approx(0.3 * row["steps_per_s"] / 3, rel=1e-6)
    assert "steps/s" in stdout and "envs.json" in stdout


def test_bench_envs_puts_the_pybullet_floor_beside_the_fused_runner(tmp_path: Path) -> None:
    stdout, rows = bench_envs(tmp_path, "fused,floor", "2", 2)
    assert [(r["backend"], r["vehicles"]) for r in rows] == [("fused", 2), ("floor", 2)]
    fused, floor = rows
    # the floor steps as many control ticks as the fused rows: 2 steps of 12 at 120 Hz
    assert floor["steps"] == 24 and floor["real_time_factor"] == pytest.approx(
        0.2 / (24 / floor["steps_per_s"]), rel=1e-6
    )
    ratio = fused["cpu_real_time_factor"] / floor["cpu_real_time_factor"]
    table = stdout.split("/ floor", 1)[1].splitlines()[1].split()
    assert table[0] == "2" and table[-1] == f"{ratio:.2f}x", stdout
    assert table[-2] == "-"  # no PyFlyt row in this run


def test_bench_envs_names_an_unknown_backend(tmp_path: Path) -> None:
    res = run_cli(["bench", "envs", "--backends", "fused,warp", "--out", str(tmp_path)])
    assert res.returncode != 0
    assert "--backends" in res.stderr and "warp" in res.stderr
    assert "Traceback" not in res.stderr


def test_bus_backend_attaches_to_a_running_stack_and_flies_it(tmp_path: Path) -> None:
    scenario = load_scenario()
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    # Real time: a world that runs on its own must not outrun the environment by more than the
    # offboard timeout between two steps (docs/envs.md), whatever the machine's load.
    scenario = msgspec.structs.replace(
        scenario,
        network=msgspec.structs.replace(scenario.network, connect=[endpoint]),
        time=msgspec.structs.replace(scenario.time, mode="realtime"),
    )
    path = write_scenario(scenario, tmp_path / "scenario.toml")
    opts = LaunchOptions(
        node_command=NODE_COMMAND,
        scenario_path=path,
        headless=True,
        run_dir=tmp_path,
        roles=("router", "plume", "physics", "autopilot"),
        verbose=0,
    )
    with Launcher(scenario, opts):
        env = PlumeSwarmEnv(scenario, backend="bus", attach=endpoint)
        try:
            start, first = env.reset(seed=1)
            upwind = {a: np.array([-1.0, 0.0, 0.0, 0.0], dtype=np.float32) for a in env.agents}
            for _ in range(10):  # >= 1 s (the world runs at its own pace) toward -x
                obs, _, _, _, infos = env.step(upwind)
        finally:
            env.close()
    for agent in env.possible_agents:
        assert start[agent][2] > 7.0, "taken off to the [env] box's altitude"
        elapsed = infos[agent]["sim_time_s"] - first[agent]["sim_time_s"]
        assert elapsed >= 1.0
        moved = start[agent][0] - obs[agent][0]
        # from hover, at most 5 m/s (and a little overshoot)
        assert 1.0 < moved <= 5.0 * elapsed + 0.5, (agent, moved, elapsed)


@pytest.mark.parametrize(
    ("env_section", "field", "words"),
    [
        ("start_min_enu_m = [50.0, 0.0, 8.0]\nstart_max_enu_m = [40.0, 5.0, 9.0]",
         "env.start_max_enu_m", "x 40.0 is below"),
        ("start_min_enu_m = [30.0, 0.0, 0.0]\nstart_max_enu_m = [40.0, 5.0, 9.0]",
         "env.start_min_enu_m", "must be > 0"),
        ("success_radius_m = 0.0", "env.success_radius_m", ""),
        ("start_box = 3", "env.start_box", "unknown key"),
    ],
)  # fmt: skip
def test_a_bad_env_section_names_its_field(env_section: str, field: str, words: str) -> None:
    text = f'[env]\n{env_section}\n[[vehicles]]\nid = "a"\n'
    with pytest.raises(ScenarioError) as err:
        parse_scenario(text, "sc.toml")
    assert err.value.field == field
    assert words in err.value.reason


def _wind_entries(scenario: object, steps: int) -> list[tuple[float, np.ndarray, np.ndarray]]:
    """(sim time, position, wind entry) of every agent after each of ``steps`` zero actions."""
    env = PlumeSwarmEnv(scenario)  # type: ignore[arg-type]
    out = []
    try:
        env.reset(seed=3)
        for _ in range(steps):
            obs, *_ = env.step({a: np.zeros(4, dtype=np.float32) for a in env.agents})
            states = env.backend.states()
            for agent, o in obs.items():
                out.append((states[agent].sim_time_s, o[0:3].copy(), o[6:9].copy()))
    finally:
        env.close()
    return out


def test_the_wind_entry_is_the_vehicles_anemometer() -> None:
    """Entries 6-8 are what the vehicle's anemometer reads. Steady wind, no noise: the scenario's
    wind vector (from 240 deg at 4 m/s: the air moves toward 60 deg, closed form). Meandering
    wind: it changes from step to step and is the wind the physics applies at the vehicle's
    position and time (plume_atmosphere.wind), not the mean. Noise: scattered around the true wind
    with
    the anemometer's standard deviation."""
    base = load_scenario(None)
    wind = msgspec.structs.replace(base.wind, speed_m_s=4.0, from_deg=240.0)
    quiet = msgspec.structs.replace(base.anemometer, noise_std_m_s=0.0)
    steady = msgspec.structs.replace(base, wind=wind, anemometer=quiet)
    to = math.radians(240.0 + 180.0)
    expected = np.array([4.0 * math.sin(to), 4.0 * math.cos(to), 0.0])
    for _, _, w in _wind_entries(steady, 5):
        assert np.allclose(w, expected, atol=1e-9), w

    meander = msgspec.structs.replace(
        steady,
        wind=msgspec.structs.replace(wind, model="meander", meander=WindMeander(preset="large")),
    )
    model = wind_from_scenario(meander)
    seen = _wind_entries(meander, 8)
    for t, position, w in seen:
        assert np.allclose(w, model.velocity([position], t)[0], atol=1e-6), (t, w)
    spread = np.ptp(np.array([w for _, _, w in seen]), axis=0)
    assert spread[:2].max() > 0.05, spread  # the mean wind would not move at all

    noisy = msgspec.structs.replace(
        steady, anemometer=msgspec.structs.replace(quiet, noise_std_m_s=0.5)
    )
    errors = np.array([w - expected for _, _, w in _wind_entries(noisy, 40)])
    assert errors.shape[0] >= 100
    assert abs(errors.mean()) < 0.1 and 0.4 < errors.std() < 0.6, (errors.mean(), errors.std())


@pytest.mark.browser
@pytest.mark.skipif(CHROMIUM is None, reason="Debian's chromium is not installed")
def test_human_render_mode_serves_the_viewer_with_every_vehicle() -> None:
    """``render_mode="human"`` opens the meshcat viewer: a page on 127.0.0.1 whose scene tree
    holds every vehicle, the source and the plume's surfaces (read in headless Chromium)."""
    env = PlumeSwarmEnv(render_mode="human")
    try:
        env.reset(seed=2)
        for _ in range(3):
            env.step({a: np.zeros(4, dtype=np.float32) for a in env.agents})
        assert env.render() is None
        url = env.viewer_url
        assert url is not None and url.startswith("http://127.0.0.1:"), url
        names = ["vehicles", "source", "plume", "level_0", *env.possible_agents]
        with chromium_page(url, 800, 500) as page:
            wait_for_scene_nodes(page, names, 120_000)
    finally:
        env.close()
    assert env.viewer_url is None  # closed with the environment, and so is its web server:
    port = int(url.split(":")[2].split("/")[0])
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", port), timeout=5.0).close()
    gc.collect()  # a socket the viewer left open warns here (an unraisable warning fails the test)
