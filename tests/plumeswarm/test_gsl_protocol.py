"""The protocol of ``plumeswarm bench gsl``: environments from files, algorithms from outside
the package, the columns' definitions, the paired test, parameters and sweeps."""

from __future__ import annotations

import hashlib
import importlib
import json
import math
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from agents.behavior import BehaviorContext, load_behavior
from plumeswarm.cli.common import comma_list
from plumeswarm.gsl.bench import make_options, row_of, rows_of, run_all
from plumeswarm.gsl.episode import (
    EpisodeSpec,
    Outcome,
    environment_field,
    episode_scenario,
    run_episode,
)
from plumeswarm.gsl.registry import (
    SENSORS,
    GslError,
    apply_overrides,
    load_environment,
    registered_algorithms,
    resolve_algorithm,
    tuned_behavior,
)
from plumeswarm.gsl.stats import mcnemar_exact, summarise
from plumeswarm.gsl.sweep import SweepParam, run_sweep, tuning_warning, write_sweep
from tests.support.procs import REPO, run_cli

# A behaviour from outside the package: two vehicles fly upwind (−x in every environment
# here) at 3 m/s and declare where they are after ``declare_after_s`` (5 s).
OUTSIDE = """
from agents.behavior import SourceEstimate
from agents.behaviors.steering import fly, hold_at


class Upwind:
    vehicles = 2
    source = "a test"
    speed_m_s = 3.0
    declare_after_s = 5.0

    def __init__(self, ctx):
        self.t0 = None
        self.declaration = None

    def step(self, own, peers, readings):
        if self.declaration is not None:
            return hold_at(self.declaration.x_m, self.declaration.y_m, own.position_enu_m[2])
        self.t0 = own.sim_time_s if self.t0 is None else self.t0
        if own.sim_time_s - self.t0 >= self.declare_after_s:
            x, y, _ = own.position_enu_m
            self.declaration = SourceEstimate(x, y, own.sim_time_s)
        return fly(own, (-self.speed_m_s, 0.0), own.position_enu_m[2])
"""


@pytest.fixture
def outside(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    """``outside_behavior:Upwind`` importable, and an installed distribution registering it
    as ``upwind`` in the ``plumeswarm.behaviors`` entry points."""
    (tmp_path / "outside_behavior.py").write_text(OUTSIDE)
    dist = tmp_path / "outside_behavior-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: outside-behavior\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text(
        "[plumeswarm.behaviors]\nupwind = outside_behavior:Upwind\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    registered_algorithms.cache_clear()
    yield tmp_path
    registered_algorithms.cache_clear()
    sys.modules.pop("outside_behavior", None)


def test_a_behaviour_from_outside_the_package_is_benchmarked(outside: Path) -> None:
    opts = make_options(
        ["mine=outside_behavior:Upwind"], ["steady_gaussian"], ["ideal"], runs=2, jobs=1
    )
    assert opts.algorithms == ("random_walk", "mine", "oracle")
    outcomes = [o for o in run_all(opts) if o.spec.algorithm == "mine"]
    (row,) = rows_of(opts, outcomes)
    assert (row["algorithm"], row["vehicles"], row["declared_rate"]) == ("mine", 2, 1.0)
    # 5 s at 3 m/s upwind (the point mass flies its velocity), declared on the tick it is
    # 5 s in: 15 m, to within one 0.05 s tick
    assert row["path_length_m"] == pytest.approx(15.0, abs=0.2)
    for o in outcomes:
        assert o.declared_s == pytest.approx(5.0, abs=0.051)
        assert o.estimate_xy[0] == pytest.approx(o.start_xy[0] - 15.0, abs=2.2)  # on the circle


def test_an_entry_point_registers_a_behaviour_by_name(outside: Path) -> None:
    name, algo = resolve_algorithm("upwind")
    assert (name, algo.behavior, algo.vehicles) == ("upwind", "outside_behavior:Upwind", 2)
    assert "upwind" in make_options(["all"], ["steady_gaussian"], ["ideal"]).algorithms


def test_the_command_line_benchmarks_a_behaviour_on_pythonpath(outside: Path) -> None:
    out = outside / "out"
    env = dict(os.environ, PYTHONPATH=f"{REPO}{os.pathsep}{outside}")
    args = ["--algorithms", "mine=outside_behavior:Upwind", "--environments", "steady_gaussian"]
    args += ["--sensors", "ideal", "--runs", "1", "--time-limit", "10", "--jobs", "1"]
    res = subprocess.run(
        [sys.executable, "-m", "plumeswarm", "bench", "gsl", *args, "--out", str(out)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert res.returncode == 0, res.stderr
    rows = json.loads((out / "gsl.json").read_text())
    assert [r["algorithm"] for r in rows] == ["random_walk", "mine", "oracle"]
    assert (
        "plumeswarm bench gsl --algorithms mine=outside_behavior:Upwind"
        in (out / "gsl.md").read_text()
    )


def _outcome(declared: bool, error_m: float, min_distance_m: float, run: int = 0) -> Outcome:
    spec = EpisodeSpec("x", "steady_gaussian", "ideal", run, 0)
    return Outcome(
        spec=spec,
        success=declared and error_m <= 2.0,
        time_to_success_s=10.0 if declared and error_m <= 2.0 else None,
        path_length_m=50.0,
        initial_distance_m=40.0,
        final_error_m=error_m,
        detections_per_min=0.0,
        declared=declared,
        estimate_xy=(error_m, 0.0),
        min_distance_m=min_distance_m,
    )


def test_the_columns_follow_their_definitions() -> None:
    outcomes = [
        _outcome(True, 1.0, 0.5),  # a success
        _outcome(True, 3.0, 3.0),  # a false declaration, within 5 m
        _outcome(True, 9.0, 1.5),  # a false declaration beyond 5 m, passed within 2 m
        _outcome(False, 1.8, 1.8),  # ends within 2 m, never declares: not a success
        _outcome(False, 30.0, 4.0),
    ]
    row = summarise(outcomes)
    assert row["success_rate"] == 0.2  # declared within 2 m: 1 of 5
    assert row["declared_5m_rate"] == 0.4
    assert row["false_declaration_rate"] == 0.4  # declared, but not within 2 m
    assert row["reached_2m_rate"] == 0.6  # came within 2 m at some time: 0.5, 1.5, 1.8
    assert row["reached_5m_rate"] == 1.0
    assert row["declared_rate"] == 0.6
    assert row["success_rate"] + row["false_declaration_rate"] + (1 - row["declared_rate"]) == 1
    # Wilson 95 % for 1 of 5 (Newcombe 1998's method 3): 0.0362–0.6245
    assert row["success_ci95"] == pytest.approx([0.036, 0.624], abs=1e-3)


@pytest.mark.parametrize(("only_a", "only_b"), [(1, 9), (0, 6), (3, 4), (12, 2)])
def test_mcnemar_exact_is_the_binomial_tail_of_the_discordant_pairs(
    only_a: int, only_b: int
) -> None:
    n = only_a + only_b
    k = min(only_a, only_b)
    expected = min(1.0, 2 * sum(math.comb(n, i) for i in range(k + 1)) / 2**n)
    a = [True] * only_a + [False] * only_b + [True] * 5 + [False] * 7  # + concordant runs
    b = [False] * only_a + [True] * only_b + [True] * 5 + [False] * 7
    assert mcnemar_exact(a, b) == (only_a, only_b, pytest.approx(expected, rel=1e-9))
    assert mcnemar_exact([True, False], [True, False]) == (0, 0, 1.0)


def test_an_environment_is_any_scenario_file(tmp_path: Path) -> None:
    """A source at (100, −50) in a wind from the north (blowing toward −y): the starts are
    30–80 m south of it, the oracle flies there at 2 m/s (≤ 85 m in 60 s) and declares it."""
    path = tmp_path / "north_wind.toml"
    path.write_text(
        "# a test environment\n[wind]\nspeed_m_s = 4.0\nfrom_deg = 0.0\n"
        "[plume]\n[[plume.sources]]\nx_m = 100.0\ny_m = -50.0\n"
    )
    opts = make_options(["oracle"], [str(path)], ["ideal"], runs=2, time_limit_s=60.0, jobs=1)
    outcomes = run_all(opts)
    rows = rows_of(opts, outcomes)
    assert {r["environment"] for r in rows} == {"north_wind"}
    assert all(not r["time_dependent"] for r in rows)
    assert rows[0]["scenario_sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    for o in outcomes:
        assert -50.0 - 80.0 <= o.start_xy[1] <= -50.0 - 30.0
        assert 100.0 - 20.0 <= o.start_xy[0] <= 100.0 + 20.0
    assert rows[-1]["algorithm"] == "oracle" and rows[-1]["success_rate"] == 1.0
    path.write_text(path.read_text().replace("[plume]\n", '[plume]\nmodel = "puff"\n'))
    assert load_environment(str(path)).time_dependent
    with pytest.raises(GslError, match=r"'nowhere'.*steady_gaussian"):
        make_options([], ["nowhere"], [])


def test_scenario_overrides_change_the_field_as_the_physics_says() -> None:
    """The Gaussian plume is linear in the release rate: Q = 5 g/s halves it everywhere."""
    spec = EpisodeSpec("casting", "steady_gaussian", "ideal", 0, 0)
    halved = EpisodeSpec(
        "casting", "steady_gaussian", "ideal", 0, 0,
        overrides=(("plume.sources.release_rate_g_s", 5.0),),
    )  # fmt: skip
    points = np.array([[20.0, 0.5, 10.0], [50.0, -2.0, 9.0]])
    full, _ = environment_field(episode_scenario(spec))
    half, _ = environment_field(episode_scenario(halved))
    np.testing.assert_allclose(half(points, 0.0), 0.5 * full(points, 0.0), rtol=1e-12)
    small = (("wind.meander.preset", "small"),)
    spec = EpisodeSpec("casting", "farrell2002_reference", "ideal", 0, 0, overrides=small)
    assert episode_scenario(spec).wind.meander.gain == 3.0  # Farrell's "small" G (file: "large")
    with pytest.raises(GslError, match="no 'nope' there"):
        apply_overrides(load_environment("meander_high").scenario, [("plume.nope", 1)])


def test_behaviour_parameters_reach_the_loader_every_runner_uses() -> None:
    name = tuned_behavior("agents.behaviors.random_walk:RandomWalk", {"speed_m_s": 1.0})
    scenario = load_environment("steady_gaussian").scenario
    ctx = BehaviorContext("uav1", 0, scenario, 0.05, np.random.default_rng(0))
    walker = load_behavior(name, ctx)  # the autopilot process's loader
    assert type(walker).__mro__[1].__name__ == "RandomWalk" and walker.speed_m_s == 1.0  # type: ignore[attr-defined]
    # A random walk at 1 m/s flies 1 m a second: 10 m in 10 s (2 m/s: 20 m).
    spec = EpisodeSpec("random_walk", "steady_gaussian", "ideal", 0, 0, 10.0, behavior=name)
    assert run_episode(spec).path_length_m == pytest.approx(10.0, rel=1e-6)
    with pytest.raises(GslError, match=r"no such parameter; its parameters: .*mean_run_s"):
        tuned_behavior("agents.behaviors.random_walk:RandomWalk", {"hit_memory_s": 1.0})


def test_a_tuned_algorithm_with_two_parameters_is_one_item_of_the_command_line_list() -> None:
    """The JSON's comma separates nothing; JSON that does not parse is named, not a
    traceback."""
    walk = "plumeswarm.gsl.tuned:agents.behaviors.random_walk:RandomWalk"
    tuned = walk + '?{"speed_m_s":1.0,"mean_run_s":2.0}'
    assert comma_list(f"casting, rw={tuned},oracle") == ("casting", f"rw={tuned}", "oracle")
    name, algo = resolve_algorithm(f"rw={tuned}")
    walker = getattr(importlib.import_module("plumeswarm.gsl.tuned"), tuned.partition(":")[2])
    assert (name, algo.behavior, walker.speed_m_s, walker.mean_run_s) == ("rw", tuned, 1.0, 2.0)
    with pytest.raises(GslError, match="its parameters are not JSON"):
        resolve_algorithm(f'rw={walk}?{{"a":1')


def test_a_sweep_refuses_test_seeds_and_environments_and_tables_the_start_distance(
    tmp_path: Path,
) -> None:
    """The oracle flies at 2 m/s: from 30 m downwind (≤ 36.1 m away, ±20 m crosswind) it
    arrives within the 25 s limit, from 60 m (≥ 60 m away) it cannot."""
    tuning = make_options(["oracle"], ["tune_north_c"], ["ideal"], runs=2, seed=0, jobs=1)
    with pytest.raises(GslError, match="seeds >= 1000"):
        tuning_warning(tuning, allow_test_seeds=False)
    warning = tuning_warning(tuning, allow_test_seeds=True)
    assert warning is not None and "WARNING" in warning and "test seeds" in warning
    opts = make_options(
        ["oracle"], ["steady_gaussian"], ["ideal"], runs=2, seed=1000, time_limit_s=25.0, jobs=1
    )
    with pytest.raises(GslError, match="tune_north_c, tune_randomised"):
        tuning_warning(opts, allow_test_seeds=False)
    warning = tuning_warning(opts, allow_test_seeds=False, allow_test_environments=True)
    assert warning is not None and "published tables' environments (steady_gaussian)" in warning
    params = [SweepParam("start.along_m", (30.0, 60.0))]
    (table,) = run_sweep(opts, params)
    oracle = {r["value"]: r["success_rate"] for r in table["rows"] if r["algorithm"] == "oracle"}
    assert oracle == {30.0: 1.0, 60.0: 0.0}
    md, js = write_sweep(tmp_path, opts, params, [table], warning)
    assert "**WARNING" in md.read_text() and json.loads(js.read_text())["warning"] == warning
    assert "plumeswarm bench gsl sweep start.along_m=30.0,60.0" in md.read_text()
    assert md.read_text().split("```")[1].strip().endswith("--allow-test-environments")


def test_the_sensor_column_has_the_pid() -> None:
    assert SENSORS["pid"].missing is None
    spec = EpisodeSpec("casting", "steady_gaussian", "pid", 0, 0, 5.0)
    sensor = episode_scenario(spec).sensor.resolved()
    assert sensor.rise_s == pytest.approx(3.0 / math.log(10), abs=0.01)  # MiniPID T90 < 3 s
    opts = make_options(["casting"], ["steady_gaussian"], ["pid"], runs=1, time_limit_s=20.0)
    outcomes = run_all(opts)
    assert row_of(outcomes[1:2])["sensor"] == "pid"


def test_the_command_line_refuses_a_sweep_on_test_seeds_and_a_bad_parameter() -> None:
    res = run_cli(["bench", "gsl", "sweep", "behavior.lost_s=0.5,1", "--seed", "0"])
    assert res.returncode == 2 and "seeds >= 1000" in res.stderr
    res = run_cli(
        ["bench", "gsl", "sweep", "behavior.lost_s=0.5,1", "--environments", "meander_low"]
    )
    assert res.returncode == 2 and "--allow-test-environments" in res.stderr
    res = run_cli(["bench", "gsl", "sweep", "plume.nope=1", "--runs", "1"])
    assert res.returncode == 2 and "no 'nope' there" in res.stderr
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize(
    ("environment", "along_m", "expected_s"),
    [
        ("steady_gaussian", (30.0, 80.0), 0.0),  # nothing to wait for
        ("meander_low", (30.0, 80.0), 60.0),  # 1.5 × 80 m / 6 m/s = 20 s < 60 s
        ("meander_high", (300.0, 300.0), 75.0),  # 1.5 × 300 m / 6 m/s
        ("farrell2002_reference", (30.0, 80.0), 120.0),  # 1.5 × 80 m / 1 m/s
    ],
)
def test_the_warm_up_lets_the_release_reach_past_the_farthest_start(
    environment: str, along_m: tuple[float, float], expected_s: float
) -> None:
    from plumeswarm.gsl.episode import start_s

    assert start_s(load_environment(environment).scenario, along_m) == pytest.approx(expected_s)
