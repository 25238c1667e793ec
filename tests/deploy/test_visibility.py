"""Where a sensor sees the mean plume (deploy.visibility, ``plumeswarm plume visibility``),
checked against the Gaussian plume's closed form and the seed's published band."""

from __future__ import annotations

import json
import math

import msgspec
import numpy as np
import pytest

from deploy.visibility import floor_multiple, visibility
from plume_atmosphere.dispersion import dispersion_curves
from swarmbus.scenario import Scenario, Sensor, load_scenario, resolve_scenario_path
from tests.support.procs import run_cli

# novak2018: Q 10 g/s, u 6 m/s, H 10 m, class D with the seed's coefficients, no lid
Q_G_S, U_M_S, H_M = 10.0, 6.0, 10.0
CURVES = dispersion_curves("novak2018", "D")
ETHANOL_PPM_PER_G_M3 = 8.314462618 * 298.15 / 101325.0 / (2 * 12.011 + 6 * 1.008 + 15.999) * 1e6


def _scenario() -> Scenario:
    return load_scenario(resolve_scenario_path("novak2018"))


def _axis_g_m3(x_m: float, z_m: float = H_M) -> float:
    """The closed form on the axis (y = 0) at height z, ground image included."""
    sy, sz = (float(v[0]) for v in CURVES.sigmas(np.array([x_m])))
    vertical = math.exp(-0.5 * ((z_m - H_M) / sz) ** 2) + math.exp(-0.5 * ((z_m + H_M) / sz) ** 2)
    return Q_G_S / (2 * math.pi * U_M_S * sy * sz) * vertical


def _sigma_y(x_m: float) -> float:
    return float(CURVES.sigmas(np.array([x_m]))[0][0])


def test_the_seed_window_reaches_50_2_m_as_published() -> None:
    """The seed's 0.01 g/m³ detection limit holds on the axis at 10 m up to x ≈ 50.2 m."""
    v = visibility(_scenario(), Sensor(preset="novak2018"), altitude_m=10.0)
    assert v.floor_g_m3 == 0.01
    assert v.farthest_m == pytest.approx(50.2, abs=0.05)


@pytest.mark.parametrize("margin", [1.0, 3.0])
def test_mox_reach_and_widths_follow_the_closed_form(margin: float) -> None:
    floor = (62.32 / 21.0) ** (1 / 0.7155) / ETHANOL_PPM_PER_G_M3  # 4.57 ppm of ethanol
    v = visibility(_scenario(), Sensor(preset="mox-tgs2620"), altitude_m=10.0, margin=margin)
    assert v.floor_g_m3 == pytest.approx(floor, rel=1e-9)
    level = margin * floor
    assert v.level_g_m3 == pytest.approx(level, rel=1e-12)
    assert v.farthest_m is not None and math.isfinite(v.farthest_m)
    assert _axis_g_m3(v.farthest_m) == pytest.approx(level, rel=1e-6)
    assert _axis_g_m3(v.farthest_m + 0.5) < level  # the axis value falls downwind
    for x, width in v.half_width_m.items():
        centre = _axis_g_m3(x)
        assert v.centreline_g_m3[x] == pytest.approx(centre, rel=1e-9)
        expected = _sigma_y(x) * math.sqrt(2 * math.log(centre / level)) if centre > level else 0
        assert width == pytest.approx(expected, rel=1e-6, abs=1e-9)


def test_a_fast_pid_sees_farther_than_the_mox_and_ideal_sees_everything() -> None:
    sc = _scenario()
    mox = visibility(sc, Sensor(preset="mox-tgs2620"))
    pid = visibility(sc, Sensor(preset="pid-fast"))
    assert mox.farthest_m is not None and pid.farthest_m is not None
    assert pid.farthest_m > 5 * mox.farthest_m
    assert _axis_g_m3(pid.farthest_m) == pytest.approx(pid.floor_g_m3, rel=1e-6)
    ideal = visibility(sc, Sensor(preset="ideal"))
    assert ideal.floor_g_m3 == 0.0 and ideal.farthest_m == math.inf
    assert all(w == math.inf for w in ideal.half_width_m.values())


def test_floor_multiple_at_a_start_is_the_mean_over_the_floor() -> None:
    sc = _scenario()
    floor = (62.32 / 21.0) ** (1 / 0.7155) / ETHANOL_PPM_PER_G_M3
    ratio = floor_multiple(sc, Sensor(preset="mox-tgs2620"), (30.0, 0.0, 10.0))
    assert ratio == pytest.approx(_axis_g_m3(30.0) / floor, rel=1e-9)
    assert floor_multiple(sc, Sensor(preset="ideal"), (30.0, 0.0, 10.0)) == math.inf
    assert floor_multiple(sc, Sensor(preset="ideal"), (-30.0, 0.0, 10.0)) == 0.0


def test_the_axis_follows_the_wind_and_the_source() -> None:
    """Turning the wind and moving the source moves the region with them."""
    sc = _scenario()
    source = msgspec.structs.replace(sc.plume.sources[0], x_m=100.0, y_m=-40.0)
    turned = msgspec.structs.replace(
        sc,
        wind=msgspec.structs.replace(sc.wind, from_deg=0.0),
        plume=msgspec.structs.replace(sc.plume, sources=[source]),
    )
    a = visibility(sc, Sensor(preset="mox-tgs2620"))
    b = visibility(turned, Sensor(preset="mox-tgs2620"))
    assert b.farthest_m == pytest.approx(a.farthest_m, rel=1e-9)
    assert b.half_width_m == pytest.approx(a.half_width_m, rel=1e-9)


def test_cli_reports_the_region_and_rejects_bad_input() -> None:
    res = run_cli(
        ["plume", "visibility", "novak2018", "--sensor", "mox-tgs2620", "--format", "json"]
    )
    assert res.returncode == 0, res.stderr
    out = json.loads(res.stdout)
    floor = (62.32 / 21.0) ** (1 / 0.7155) / ETHANOL_PPM_PER_G_M3
    assert out["floor_g_m3"] == pytest.approx(floor, rel=1e-9)
    assert _axis_g_m3(out["farthest_m"]) == pytest.approx(floor, rel=1e-6)
    assert [row["downwind_m"] for row in out["at"]] == [30.0, 50.0, 80.0]
    table = run_cli(["plume", "visibility", "novak2018", "--sensor", "pid", "--at", "40"])
    assert table.returncode == 0, table.stderr
    assert "floor" in table.stdout and "40" in table.stdout
    for bad in (["--margin", "0"], ["--altitude", "-5"], ["--at", "-1"]):
        res = run_cli(["plume", "visibility", "novak2018", *bad])
        assert res.returncode != 0
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("plumeswarm: error:"), res.stderr
