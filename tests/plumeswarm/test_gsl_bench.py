"""``plumeswarm bench gsl``: same seed → same bytes, the statistics, the refusals."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any

import pytest

from plumeswarm.gsl.bench import (
    floor_multiple_at_farthest_start,
    make_options,
    rows_of,
    run_all,
    throughput_lines,
    write_outputs,
)
from plumeswarm.gsl.episode import (
    START_ACROSS_M,
    START_ALONG_M,
    EpisodeSpec,
    fused_episode,
    run_episode,
    start_point,
)
from plumeswarm.gsl.registry import BUILTIN_ALGORITHMS, ENVIRONMENTS_DIR, load_environment
from plumeswarm.gsl.stats import wilson_interval
from tests.support.procs import run_cli


@pytest.mark.parametrize(
    ("successes", "runs", "low", "high"),
    # Newcombe (1998), Statistics in Medicine 17:857, Table I, method 3 (Wilson score).
    [
        (81, 263, 0.2553, 0.3662),
        (15, 148, 0.0624, 0.1605),
        (0, 20, 0.0, 0.1611),
        (1, 29, 0.0061, 0.1718),
    ],
)
def test_wilson_interval_matches_newcombe(successes: int, runs: int, low: float, high: float):
    got = wilson_interval(successes, runs)
    assert got == pytest.approx((low, high), abs=1e-4)


def test_starts_are_inside_the_protocol_box() -> None:
    sc = load_environment("steady_gaussian").scenario  # source at the origin, wind toward +x
    for run in range(200):
        x, y = start_point(sc, 7, run)
        assert START_ALONG_M[0] <= x <= START_ALONG_M[1]
        assert START_ACROSS_M[0] <= y <= START_ACROSS_M[1]


TABLE_FILES = ("gsl.md", "gsl.json", "paired.json", "runs.csv")


def _table_bytes(
    out: Path, cell: tuple[list[str], list[str], list[str]], **options: Any
) -> tuple[bytes, ...]:
    """The bench's table files (``TABLE_FILES``) for ``cell`` — algorithms, environments,
    sensors — and ``options``, written to ``out``."""
    opts = make_options(*cell, **options)
    outcomes = run_all(opts)
    write_outputs(out, opts, rows_of(opts, outcomes), outcomes)
    return tuple((out / name).read_bytes() for name in TABLE_FILES)


def test_same_seed_same_table_byte_for_byte(tmp_path: Path) -> None:
    cell = (["random_walk", "casting"], ["steady_gaussian"], ["ideal"])
    options: dict[str, Any] = {"runs": 2, "seed": 4, "time_limit_s": 20.0}
    first = _table_bytes(tmp_path / "a", cell, jobs=1, **options)
    second = _table_bytes(tmp_path / "b", cell, jobs=2, **options)
    assert first == second
    rows = json.loads(first[1])
    # the floor and the ceiling run in every cell
    assert [r["algorithm"] for r in rows] == ["random_walk", "casting", "oracle"]
    for row in rows:
        assert {
            "algorithm",
            "environment",
            "sensor",
            "runs",
            "success_rate",
            "success_ci95",
            "median_time_s",
            "path_ratio",
            "final_error_m",
        } <= set(row)
        assert row["runs"] == 2 and row["environment"] == "steady_gaussian"
        assert row["time_dependent"] is False
        file = ENVIRONMENTS_DIR / "steady_gaussian.toml"
        assert row["scenario_sha256"] == hashlib.sha256(file.read_bytes()).hexdigest()
    # 3 algorithms × 2 runs, one line each under the header
    assert len(first[3].decode().splitlines()) == 1 + 3 * 2
    for name in ("trajectories_steady_gaussian", "success", "final_error"):
        assert (tmp_path / "a" / f"{name}.png").stat().st_size > 10_000


def test_same_seed_same_filament_cell_byte_for_byte(tmp_path: Path) -> None:
    """A time-dependent field, its anemometer and the MOX sensor repeat their bits too."""

    cell = (["casting"], ["meander_high"], ["mox"])
    options: dict[str, Any] = {"runs": 2, "seed": 4, "time_limit_s": 20.0}
    first = _table_bytes(tmp_path / "a", cell, jobs=1, **options)
    assert first == _table_bytes(tmp_path / "b", cell, jobs=2, **options)
    _, row, _ = json.loads(first[1])
    assert (row["environment"], row["sensor"], row["runs"]) == ("meander_high", "mox", 2)
    assert row["time_dependent"] is True


def test_same_seed_same_full_dynamics_table_byte_for_byte(tmp_path: Path) -> None:
    """Full dynamics (pybullet vehicles and autopilots in each worker) repeat their bits
    whatever the number of workers: the published full-dynamics table's claim."""
    cell = (["casting"], ["steady_gaussian"], ["ideal"])
    options: dict[str, Any] = {"runs": 2, "seed": 4, "time_limit_s": 10.0, "dynamics": "full"}
    first = _table_bytes(tmp_path / "a", cell, jobs=1, **options)
    assert first == _table_bytes(tmp_path / "b", cell, jobs=2, **options)
    rows = json.loads(first[1])
    assert [(r["algorithm"], r["dynamics"], r["runs"]) for r in rows] == [
        ("random_walk", "full", 2),
        ("casting", "full", 2),
        ("oracle", "full", 2),
    ]
    # every episode flew: more than 1 m of path in every per-run line
    lines = first[3].decode().splitlines()
    assert len(lines) == 1 + 3 * 2
    path = lines[0].split(",").index("path_length_m")
    assert all(float(line.split(",")[path]) > 1.0 for line in lines[1:])


def test_missing_environments_and_unknown_algorithms_are_refused_clearly() -> None:
    res = run_cli(["bench", "gsl", "--environments", "filament", "--runs", "1"])
    assert res.returncode == 2
    assert "'filament'" in res.stderr and "meander_high" in res.stderr
    assert "Traceback" not in res.stderr
    res = run_cli(["bench", "gsl", "--algorithms", "moth", "--runs", "1"])
    assert res.returncode == 2 and "'moth'" in res.stderr and "casting" in res.stderr


def test_full_dynamics_takes_off_and_casting_climbs_the_plume() -> None:
    opts = make_options(["casting"], [], [], runs=1, time_limit_s=20.0, dynamics="full")
    assert (opts.control_hz, opts.sensor_period_ticks) == (120, 12)  # the scenario's rates
    spec = EpisodeSpec("casting", "steady_gaussian", "ideal", 1, 0, 20.0, 120, 12, True, "full")
    outcome = run_episode(spec)
    track = outcome.trajectories[0]
    # It starts hovering over its start point (taken off there) and surges upwind (−x).
    start = start_point(load_environment("steady_gaussian").scenario, 0, 1)
    assert math.dist(track[0], start) < 1.0
    assert track[-1][0] < track[0][0] - 20.0
    assert outcome.final_error_m < outcome.initial_distance_m - 20.0


@pytest.mark.parametrize("algorithm", sorted(BUILTIN_ALGORITHMS))
def test_every_registered_algorithm_flies_an_episode(algorithm: str) -> None:
    outcome = run_episode(EpisodeSpec(algorithm, "steady_gaussian", "ideal", 0, 0, 5.0))
    assert outcome.path_length_m > 1.0  # it moved
    assert outcome.initial_distance_m > 25.0


def test_full_dynamics_in_a_time_dependent_plume_hovers_until_the_release_has_spread() -> None:
    """The vehicles take off and hold; the behaviours fly from 60 s of sim time on (the
    offboard switch at the boundary before tick 60 s × 120 Hz), and the episode's clock with
    them: a 5 s limit ends 5 s later."""
    spec = EpisodeSpec("surge_cast", "meander_low", "mox", 0, 0, 5.0, 120, 12, False, "full")
    outcome, schedule = fused_episode(spec)
    assert sorted(schedule.commands) == [0, 60 * 120 - 1]
    assert schedule.last_tick == 60 * 120 + 5 * 120
    assert 5.0 < outcome.path_length_m < 5.0 * 5.0  # flew for 5 s, at most 5 m/s


def _class_d_centreline_g_m3(x_m: float, q_g_s: float = 10.0, u_m_s: float = 6.0) -> float:
    """The Gaussian plume on its axis at the release height H = 10 m, with ground reflection:
    Q / (2π u σy σz) · (1 + e^(−2H²/σz²)), McMullen's (1975) class D σ = exp(I + J ln x +
    K ln² x), x in km: σy (4.230, 0.9222, −0.0087), σz (3.414, 0.7371, −0.0316)."""
    ln_km = math.log(x_m / 1000.0)
    sigma_y = math.exp(4.230 + 0.9222 * ln_km - 0.0087 * ln_km**2)
    sigma_z = math.exp(3.414 + 0.7371 * ln_km - 0.0316 * ln_km**2)
    reflection = 1.0 + math.exp(-2.0 * 10.0**2 / sigma_z**2)
    return q_g_s / (2.0 * math.pi * u_m_s * sigma_y * sigma_z) * reflection


#: Detection floors (g/m³, 298.15 K, 1 atm: molar volume 0.0244654 m³/mol): the MiniPID's
#: datasheet 0.1 ppm of isobutylene (56.106 g/mol); the TGS2620 curve's clean-air end, 4.57 ppm
#: of ethanol (46.068 g/mol).
_MOLAR_VOLUME_M3 = 8.314462618 * 298.15 / 101_325.0
PID_FLOOR_G_M3 = 0.1e-6 * 56.106 / _MOLAR_VOLUME_M3
MOX_FLOOR_G_M3 = 4.57e-6 * 46.068 / _MOLAR_VOLUME_M3


def test_the_floor_multiple_at_the_farthest_start_is_the_gaussians_over_the_floor(
    tmp_path: Path,
) -> None:
    """meander_high's time average is class D's Gaussian: at 80 m on the axis ≈ 0.0109 g/m³,
    1.26 × the MOX floor (flagged: below 3) and 47 × the PID's; the ideal sensor has no floor.
    Each gsl.json row carries it; gsl.md flags the MOX cell only."""
    mean = _class_d_centreline_g_m3(START_ALONG_M[1])
    expected = {"mox": mean / MOX_FLOOR_G_M3, "pid": mean / PID_FLOOR_G_M3}
    assert expected["mox"] < 3.0 < expected["pid"]
    for sensor, multiple in expected.items():
        got = floor_multiple_at_farthest_start("meander_high", sensor)
        assert got == pytest.approx(multiple, rel=2e-3), sensor
    assert floor_multiple_at_farthest_start("meander_high", "ideal") is None
    # A tenth of the release rate: a tenth of the mean (the Gaussian is linear in Q).
    tenth = floor_multiple_at_farthest_start(
        "meander_high", "pid", (("plume.sources.release_rate_g_s", 1.0),)
    )
    assert tenth == pytest.approx(expected["pid"] / 10.0, rel=2e-3)
    opts = make_options(
        ["oracle"], ["meander_high"], ["mox", "pid"], runs=1, time_limit_s=1.0, jobs=1
    )
    outcomes = run_all(opts)
    write_outputs(tmp_path, opts, rows_of(opts, outcomes), outcomes)
    rows = json.loads((tmp_path / "gsl.json").read_text())
    for row in rows:
        assert row["floor_multiple_at_farthest_start"] == pytest.approx(
            expected[row["sensor"]], rel=2e-3
        )
    flagged = [
        line for line in (tmp_path / "gsl.md").read_text().splitlines()
        if "the sensor cannot see the plume at the farthest starts" in line
    ]  # fmt: skip
    assert len(flagged) == 1 and "| meander_high | mox |" in flagged[0]


@pytest.mark.parametrize("jobs", [1, 2])
def test_every_episodes_cpu_time_is_counted_and_summed_per_algorithm(jobs: int) -> None:
    opts = make_options(
        ["random_walk", "casting"], ["steady_gaussian"], ["ideal"],
        runs=2, seed=4, time_limit_s=10.0, jobs=jobs,
    )  # fmt: skip
    cpu_s: dict[EpisodeSpec, float] = {}
    outcomes = run_all(opts, cpu_s=cpu_s)
    assert sorted(cpu_s, key=repr) == sorted((o.spec for o in outcomes), key=repr)
    assert all(0.0 < t < 60.0 for t in cpu_s.values())
    lines = throughput_lines(cpu_s)
    for algorithm in ("random_walk", "casting"):
        times = [t for s, t in cpu_s.items() if s.algorithm == algorithm]
        (line,) = [x for x in lines if x.split()[:2] == [algorithm, "kinematic"]]
        assert float(line.split()[2]) == pytest.approx(2 / sum(times), rel=1e-3, abs=1e-3)
