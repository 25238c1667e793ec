"""Source-seeking behaviours: each against a value derived independently of its code."""

from __future__ import annotations

import math
import platform
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from fractions import Fraction
from pathlib import Path

import msgspec
import numpy as np
import pytest

from agents.behavior import BehaviorContext
from agents.behaviors.casting import Casting
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3, PlumeDetector, detector_for, lags
from agents.behaviors.gradient_swarm import GradientSwarm, log_gradient
from agents.behaviors.infotaxis import ConcentrationInfotaxis, Infotaxis
from agents.behaviors.infotaxis_core import PlumeHitStatistics
from agents.behaviors.oracle import Oracle
from agents.behaviors.particle_filter import SourceTermFilter
from agents.behaviors.random_walk import RandomWalk
from agents.behaviors.surge_cast import SurgeCast
from agents.behaviors.tracking import AveragedWind
from agents.behaviors.wind import WindFrame
from agents.sensor import ConcentrationSensor
from plume_atmosphere.dispersion import dispersion_curves
from plume_atmosphere.plume_formula import gaussian_plume_g_m3, plume_frame
from plume_service import GaussianPlume
from swarmbus.errors import FieldError
from swarmbus.messages import PeerReading, Setpoint, VehicleState
from swarmbus.scenario import Scenario, Sensor, load_scenario
from tests.support.messages_samples import reading as noiseless_reading
from tests.support.messages_samples import vehicle_state
from tests.support.procs import run_python
from tests.support.published import REPO, published_and_reflown

SCENARIO = load_scenario()  # novak2018: wind 6 m/s from 270° (toward +x), source at the origin


def velocity(sp: Setpoint | None) -> tuple[float, float, float]:
    assert sp is not None and sp.velocity_enu_m_s is not None, sp
    return sp.velocity_enu_m_s


#: The same with the ideal sensor and a noiseless anemometer: the behaviours see the field.
IDEAL = msgspec.structs.replace(
    SCENARIO,
    sensor=Sensor(preset="ideal"),
    anemometer=msgspec.structs.replace(SCENARIO.anemometer, noise_std_m_s=0.0),
)


def ctx(
    index: int = 0, seed: int = 1, dt: float = 0.05, scenario: Scenario = IDEAL
) -> BehaviorContext:
    rng = np.random.Generator(np.random.PCG64(seed))
    return BehaviorContext(f"uav{index + 1}", index, scenario, dt, rng)


def state(x: float, y: float, t: float, vid: str = "uav1", z: float = 10.0) -> VehicleState:
    return vehicle_state(vid, 0, (x, y, z), sim_time_s=t, lat_deg=0.0, lon_deg=0.0, alt_m=z)


def reading(x: float, y: float, t: float, value: float, peers: list[PeerReading] | None = None):
    return noiseless_reading("uav1", t, (x, y, 10.0), value, peers)


# ---------------------------------------------------------------- shared forward model
def test_the_shared_formula_matches_the_plume_service() -> None:
    plume = GaussianPlume(7.0, 4.0, 8.0, "D", "novak2018", (3.0, -2.0), 250.0)
    rng = np.random.default_rng(5)
    pts = np.column_stack(
        [rng.uniform(-20, 120, 500), rng.uniform(-60, 60, 500), rng.uniform(0, 30, 500)]
    )
    x, y = plume_frame(pts[:, 0], pts[:, 1], 3.0, -2.0, 250.0)
    mine = gaussian_plume_g_m3(x, y, pts[:, 2], 7.0, 4.0, 8.0, plume.dispersion)
    np.testing.assert_allclose(mine, plume.concentration(pts), rtol=1e-10, atol=1e-300)
    assert (mine > 0).sum() > 100  # the comparison covers the plume, not only zeros


# ---------------------------------------------------------------- infotaxis
#: Hit statistics of the calibrated plume's kind (P(hit within 1 s) on the axis, its width).
STATS = PlumeHitStatistics(
    distances_m=(30.0, 50.0, 80.0), axis_p_hit_1s=(0.75, 0.6, 0.45), width_m=(2.4, 4.0, 6.3)
)


class CalibratedInfotaxis(Infotaxis):
    hit_statistics = STATS


def _laid(beh: Infotaxis) -> WindFrame:
    frame = WindFrame.of((6.0, 0.0))  # toward +x at 6 m/s
    beh.wind_sum = (6.0, 0.0, 1.0)
    beh._build_grid(frame, 50.0, 0.0)
    return frame


def _cell(beh: Infotaxis, x: float, y: float) -> int:
    assert beh.cells_xy is not None
    return int(np.argmin(np.hypot(beh.cells_xy[:, 0] - x, beh.cells_xy[:, 1] - y)))


def test_calibrated_infotaxis_predicts_the_measured_hit_statistics() -> None:
    """The likelihood of at least one hit in 1 s, for a searcher d m downwind of a cell on its
    axis, is the measured P(hit within 1 s) at d (a power law through three points: within
    0.03), and at one measured width across it is lower by the Gaussian's e^(-1/2) in rate."""
    beh = CalibratedInfotaxis(ctx())
    frame = _laid(beh)
    for d, p in zip(STATS.distances_m, STATS.axis_p_hit_1s, strict=True):
        table = beh.likelihoods(frame, 50.0, 0.0, 1.0)
        source = _cell(beh, 50.0 - d, 0.0)
        assert 1.0 - table[0, 0, source] == pytest.approx(p, abs=0.03)
    table = beh.likelihoods(frame, 50.0, 4.0, 1.0)
    rate_axis = -math.log(1.0 - 0.6)
    p_across = 1.0 - math.exp(-rate_axis * math.exp(-0.5 * (4.0 / 4.0) ** 2))
    assert 1.0 - table[0, 0, _cell(beh, 0.0, 0.0)] == pytest.approx(p_across, abs=0.05)


def test_infotaxis_a_miss_on_the_axis_costs_the_true_cell_at_most_the_miss_floor() -> None:
    """With the plume's P(hit within 1 s) of 0.75 on its axis, a model without a floor would
    multiply the true cell by e^(-r·Δt) for a miss: 0.25 for 1 s, 0.004 for 4 s (the old
    model: 1e-4–1e-2). The floor keeps any one miss from costing more than 0.25, and each
    step's evidence is weighed by ``evidence_weight`` w (the likelihood to the power w)."""
    beh = CalibratedInfotaxis(ctx())
    w = beh.evidence_weight
    assert 0.0 < w <= 1.0
    frame = _laid(beh)
    assert beh.belief is not None
    prior = beh.belief.copy()
    true, far = _cell(beh, 20.0, 0.0), _cell(beh, 40.0, 30.0)
    beh.hits = 0
    beh._update(frame, 50.0, 0.0, 4.0)
    ratio = (beh.belief[0, true] / prior[0, true]) / (beh.belief[0, far] / prior[0, far])
    assert ratio == pytest.approx((0.25 / math.exp(-0.02 * 4.0)) ** w, rel=1e-6)
    # one hit in 1 s: a cell that sees only the background (0.02 /s) explains it with
    # 0.02·e^(-0.02), the true cell (r = -ln 0.25 + 0.02 there, P(0) raised to the floor
    # 0.25 and the rest scaled by 0.75/(1 - e^(-r))) with r·e^(-r)·0.75/(1 - e^(-r))
    beh.hits = 1
    before = beh.belief.copy()
    beh._update(frame, 50.0, 0.0, 1.0)
    ratio = (beh.belief[0, far] / before[0, far]) / (beh.belief[0, true] / before[0, true])
    r = -math.log(0.25) + 0.02
    p1 = r * math.exp(-r) * 0.75 / -math.expm1(-r)
    assert ratio == pytest.approx((0.02 * math.exp(-0.02) / p1) ** w, rel=1e-6)


def test_online_infotaxis_learns_the_rate_with_the_place() -> None:
    """Without statistics the belief is over (hypothesis, cell); hits at 3 /s on the axis
    make the 3 /s hypotheses the likeliest and put the
    source upwind of the searcher, centred on its axis."""
    beh = Infotaxis(ctx())
    frame = _laid(beh)
    assert beh.belief is not None and len(beh.models) == 6
    rng = np.random.default_rng(3)
    for _ in range(30):
        beh.hits = int(rng.poisson(3.0))
        beh._update(frame, 40.0, 0.0, 1.0)
    by_model = beh.belief.sum(axis=1)
    rates = [m.axis_rate_hz for m in beh.models]
    assert rates[int(np.argmax(by_model))] == 3.0
    marginal = beh.belief.sum(axis=0)
    assert beh.cells_xy is not None
    # the source is upwind of the searcher, centred on its axis
    assert marginal[beh.cells_xy[:, 0] < 40.0].sum() > 0.999
    assert abs(float(marginal @ beh.cells_xy[:, 1])) < 0.5


@pytest.mark.parametrize("spread_m", [0.0, ConcentrationInfotaxis.release_height_spread_m])
def test_concentration_infotaxis_finds_the_source_of_a_steady_plume_from_its_readings(
    spread_m: float,
) -> None:
    """The concentration likelihood in novak2018's steady plume (Q = 10 g/s released 10 m up
    at the origin, 6 m/s toward +x): the readings of the field itself, one per step, at
    places 3–40 m downwind and ±6 m across and a few upwind of the source (reading 0), put
    0.9 of the belief within 1 m of the source. With the release height known (no spread:
    the model is the field's) the belief is on the steady regime (γ = 1: a miss where the
    mean plume has gas is not a blank) and the release rate on the hypothesis nearest 10."""

    class Known(ConcentrationInfotaxis):
        release_height_spread_m = spread_m

    beh = Known(ctx())
    frame = _laid(beh)
    assert beh.belief is not None and beh.cells_xy is not None
    curves = dispersion_curves(SCENARIO.plume.coefficients, SCENARIO.plume.stability)
    places = [
        (x, float(y)) for x in (3.0, 6.0, 10.0, 15.0, 20.0, 30.0, 40.0) for y in range(-6, 7, 2)
    ]
    places += [(x, y) for x in (-4.0, -2.0) for y in (-2.0, 0.0, 2.0)]
    for t, (x, y) in enumerate(places):
        value = float(gaussian_plume_g_m3(x, float(y), 10.0, 10.0, 6.0, 10.0, curves))
        beh._observe([reading(x, float(y), float(t), value)])
        beh._update(frame, x, float(y), 1.0)
    mx, my, spread, mass = beh._belief_mean()
    assert math.hypot(mx, my) < 1.0, (mx, my)
    assert mass >= 0.9, (mass, spread)
    if spread_m > 0.0:
        return
    by_model = beh.belief.sum(axis=1)
    steady = [k for k, (_, gamma, _) in enumerate(beh.models) if gamma == 1.0]
    assert by_model[steady].sum() > 0.99
    rate = beh.models[int(np.argmax(by_model))][0]
    nearest = min(beh.release_rates_g_s, key=lambda q: abs(math.log(q / 10.0)))
    assert rate == nearest, rate


def test_the_default_likelihood_is_hits_and_a_bad_one_is_named() -> None:
    assert Infotaxis.likelihood == "hits" and not Infotaxis(ctx()).concentration

    class Bad(Infotaxis):
        likelihood = "counts"

    with pytest.raises(FieldError, match="likelihood: 'counts': valid: hits, concentration"):
        Bad(ctx())


# ---------------------------------------------------------------- particle filter
def test_particle_filter_recovers_the_source_term_of_a_noiseless_plume() -> None:
    x0, y0, q = 3.0, -2.0, 7.0
    wind_from = 250.0
    plume = GaussianPlume(q, 5.0, 10.0, "D", "novak2018", (x0, y0), wind_from)
    rng = np.random.default_rng(11)
    n = 3000
    prior = np.column_stack(
        [rng.uniform(-40, 40, n), rng.uniform(-40, 40, n), np.exp(rng.uniform(0, math.log(50), n))]
    )
    stf = SourceTermFilter(prior, dispersion_curves("novak2018", "D"), 10.0, rng)
    toward = math.radians(wind_from + 180.0)
    dw = (math.sin(toward), math.cos(toward))
    cw = (-dw[1], dw[0])
    wind = (5.0 * dw[0], 5.0 * dw[1])
    # A lawnmower of crosswind legs 3–30 m downwind of the source, at the release height.
    for along in np.arange(30.0, 2.0, -1.5):
        for across in np.linspace(-6.0, 6.0, 13):
            px = x0 + along * dw[0] + across * cw[0]
            py = y0 + along * dw[1] + across * cw[1]
            value = float(plume.concentration([[px, py, 10.0]])[0])
            stf.update(px, py, 10.0, value, wind)
    ex, ey, eq, spread = stf.estimate()
    assert math.hypot(ex - x0, ey - y0) < 0.5, (ex, ey)
    assert abs(eq / q - 1.0) < 0.15, eq
    assert spread < 1.0


def test_the_particle_likelihood_is_zero_inflated() -> None:
    """Hand-computed from the model: P(detection | c) = 0.01 + 0.99 (1 - exp(-c / 0.001)),
    capped at 1 - 0.3; a zero has likelihood 1 - P, so a particle predicting gas loses a
    factor 0.3 / 0.99 at most (not the 7-14 sigma of a log-normal on ln(0 + eps)); a filament
    peak 100x the prediction costs at most the 3-sigma floor, exp(-4.5)."""
    stf = SourceTermFilter(
        np.zeros((1, 3)), dispersion_curves("novak2018", "D"), 10.0, np.random.default_rng(0)
    )
    predicted = np.array([0.0, 0.001, 1.0])
    p_det = [0.01, min(0.01 + 0.99 * (1.0 - math.exp(-1.0)), 0.7), 0.7]
    zero = stf.log_likelihood(predicted, 0.0)
    assert zero == pytest.approx([math.log(1.0 - p) for p in p_det], rel=1e-12)
    peak = stf.log_likelihood(np.array([0.001]), 0.1)  # ln(0.1001/0.0011) = 4.51 > 3 sigma
    assert peak[0] == pytest.approx(math.log(p_det[1]) - 4.5, rel=1e-12)
    window = stf.log_likelihood(np.array([0.001]), 0.0005, detected=True)  # a window's mean
    residual = math.log(0.0006 / 0.0011)
    assert window[0] == pytest.approx(math.log(p_det[1]) - 0.5 * (residual / 0.6) ** 2)


# ---------------------------------------------------------------- gradient swarm
def test_log_gradient_is_exact_for_an_exponential_field() -> None:
    pts = np.array([[1.0, 2.0], [3.0, -1.0], [-2.0, 0.5], [0.0, 4.0]])
    values = np.exp(-3.0 + 0.2 * pts[:, 0] - 0.7 * pts[:, 1])
    gx, gy = log_gradient(pts, values, floor_g_m3=0.0)
    assert gx == pytest.approx(0.2, abs=1e-12) and gy == pytest.approx(-0.7, abs=1e-12)


def _exact_plane_slopes(
    pts: list[tuple[float, float]], logs: list[float]
) -> tuple[Fraction, Fraction]:
    """The least-squares plane a + gx·x + gy·y through (x, y, l), in exact rationals: its
    3 × 3 normal equations (uncentred) solved by Gauss–Jordan elimination."""
    rows = [(Fraction(1), Fraction(x), Fraction(y)) for x, y in pts]
    zero = Fraction(0)
    a = [[sum((r[i] * r[j] for r in rows), zero) for j in range(3)] for i in range(3)]
    b = [sum((r[i] * Fraction(v) for r, v in zip(rows, logs, strict=True)), zero) for i in range(3)]
    for col in range(3):
        pivot = next(k for k in range(col, 3) if a[k][col] != 0)
        a[col], a[pivot], b[col], b[pivot] = a[pivot], a[col], b[pivot], b[col]
        for k in range(3):
            if k != col and a[k][col] != 0:
                f = a[k][col] / a[col][col]
                a[k] = [u - f * w for u, w in zip(a[k], a[col], strict=True)]
                b[k] -= f * b[col]
    return b[1] / a[1][1], b[2] / a[2][2]


def test_log_gradient_is_the_least_squares_plane_of_the_logarithms() -> None:
    rng = np.random.default_rng(7)
    for n in (3, 3, 4, 6):
        pts = [(float(x), float(y)) for x, y in rng.uniform(-3.0, 3.0, (n, 2)) + 50.0]
        values = [float(v) for v in np.exp(rng.uniform(-12.0, -2.0, n))]
        gx, gy = log_gradient(pts, values, 1e-4)
        ex, ey = _exact_plane_slopes(pts, [math.log(v + 1e-4) for v in values])
        assert gx == pytest.approx(float(ex), rel=1e-12)
        assert gy == pytest.approx(float(ey), rel=1e-12)


def test_log_gradient_of_collinear_readings_is_the_least_norm_slope_along_their_line() -> None:
    # t = 0, 5, 10, −5 m along (0.6, 0.8), ln c rising 0.1 per metre: no information across
    # the line, so the least-norm gradient is 0.1 × (0.6, 0.8)
    pts = [(0.0, 0.0), (3.0, 4.0), (6.0, 8.0), (-3.0, -4.0)]
    values = [math.exp(-5.0 + 0.1 * t) for t in (0.0, 5.0, 10.0, -5.0)]
    gx, gy = log_gradient(pts, values, floor_g_m3=0.0)
    assert gx == pytest.approx(0.06, rel=1e-12) and gy == pytest.approx(0.08, rel=1e-12)
    assert log_gradient([(5.0, 1.0)] * 3, [1e-3, 2e-3, 3e-3]) == (0.0, 0.0)


def blas_kernels() -> list[str]:
    """OpenBLAS core types this CPU can run (``OPENBLAS_CORETYPE``): SSE3, AVX, AVX2."""
    flags = ""
    with suppress(OSError):
        flags = Path("/proc/cpuinfo").read_text()
    kernels = ["Prescott"]
    kernels += ["Sandybridge"] if " avx " in flags else []
    kernels += ["Haswell"] if " avx2 " in flags else []
    return kernels


FITS = """
import numpy as np
from agents.behaviors.gradient_swarm import log_gradient
rng = np.random.default_rng(2026)
for _ in range(200):
    pts = rng.uniform(-3.0, 3.0, (3, 2)) + rng.uniform(0.0, 80.0, 2)
    gx, gy = log_gradient(pts, np.exp(rng.uniform(-12.0, -2.0, 3)), 1e-4)
    print(gx.hex(), gy.hex())
"""


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS core types are x86-64's")
def test_log_gradient_gives_the_same_bits_on_every_blas_kernel() -> None:
    """A swarm climbs the fitted direction: its last bit must not depend on the BLAS kernels
    the CPU selects (np.linalg.lstsq gave three answers here: AVX-512, AVX2, AVX/SSE3)."""
    outputs = {}
    for kernel in ["", *blas_kernels()]:
        done = run_python(FITS, timeout_s=60.0, env={"OPENBLAS_CORETYPE": kernel})
        assert done.returncode == 0, done.stderr
        outputs[kernel or "default"] = done.stdout
    assert len(outputs["default"].splitlines()) == 200
    assert len(set(outputs.values())) == 1, {k: v[:60] for k, v in outputs.items()}


EPISODE = """
from plumeswarm.gsl.bench import make_options, runs_csv, specs_of
from plumeswarm.gsl.episode import run_episode
opts = make_options(["gradient_swarm"], ["meander_low"], ["ideal"], runs=2, seed=0)
spec = [s for s in specs_of(opts) if s.algorithm == "gradient_swarm"][1]
print(runs_csv([run_episode(spec)]).splitlines()[1])
"""


@pytest.mark.skipif(platform.machine() != "x86_64", reason="OpenBLAS core types are x86-64's")
def test_gradient_swarm_flies_the_same_episode_on_every_blas_kernel() -> None:
    """Run 1 of gradient_swarm in meander_low (ideal sensor, test seed 0) in fresh processes
    on the machine's BLAS kernels, the AVX2 ones and the SSE3 ones: the same line of
    runs.csv, the one results/gsl-ideal has. With the fit through np.linalg.lstsq the three
    flew it to declarations at 113.75 s (AVX-512), 65.55 s (AVX2) and 126.40 s (SSE3)."""
    kernels = ["", *(k for k in blas_kernels() if k in ("Haswell", "Prescott"))]
    with ThreadPoolExecutor(len(kernels)) as pool:
        done = list(
            pool.map(
                lambda k: run_python(EPISODE, timeout_s=300.0, env={"OPENBLAS_CORETYPE": k}),
                kernels,
            )
        )
    assert all(d.returncode == 0 for d in done), [d.stderr for d in done]
    lines = {k or "default": d.stdout.strip() for k, d in zip(kernels, done, strict=True)}
    assert len(set(lines.values())) == 1, lines
    table = (REPO / "results" / "gsl-ideal" / "runs.csv").read_text().splitlines()
    published = [t for t in table if t.startswith("gradient_swarm,meander_low,ideal,kinematic,1,")]
    assert published == [lines["default"]]  # the published line is the one the code gives


def test_swarm_gradient_estimate_matches_the_analytic_gradient_of_the_plume() -> None:
    plume = GaussianPlume.preset("novak2018")  # wind toward +x, source at the origin, H 10 m
    x, y, h = 40.0, 3.0, 10.0
    # Analytic ∂/∂x, ∂/∂y of ln C at z = H from the published σ(x) = exp(I + J ln x + K ln²x)
    # (novak2018's class D: σy (−2.555, 1.0423, −0.0087), σz (−3.186, 1.1737, +0.0316)).
    lx = math.log(x)
    sy = math.exp(-2.555 + 1.0423 * lx - 0.0087 * lx * lx)
    sz = math.exp(-3.186 + 1.1737 * lx + 0.0316 * lx * lx)
    dsy = sy * (1.0423 - 2 * 0.0087 * lx) / x
    dsz = sz * (1.1737 + 2 * 0.0316 * lx) / x
    image = math.exp(-2 * h * h / sz**2)
    d_ln_g = image * (4 * h * h / sz**3) * dsz / (1 + image)
    grad_x = -dsy / sy - dsz / sz + y * y * dsy / sy**3 + d_ln_g
    grad_y = -y / sy**2
    r = 0.005  # the fit is of a plane: curvature errors scale with the spacing
    pts = np.array([[x + r * math.cos(a), y + r * math.sin(a)] for a in (0.3, 2.4, 4.5)])
    values = plume.concentration(np.column_stack([pts, np.full(3, h)]))
    gx, gy = log_gradient(pts, values)
    assert gx == pytest.approx(grad_x, rel=0.02)
    assert gy == pytest.approx(grad_y, rel=0.02)


def test_gradient_swarm_climbs_in_formation() -> None:
    plume = GaussianPlume.preset("novak2018")
    members = [GradientSwarm(ctx(i)) for i in range(3)]
    # The formation the behaviour keeps: radius 2 m, first vertex upwind (−x), by id order.
    centre = (40.0, 3.0)
    slots = [
        (centre[0] - 2 * math.cos(a), centre[1] + 2 * math.sin(a))
        for a in (0.0, 2 * math.pi / 3, 4 * math.pi / 3)
    ]
    values = plume.concentration([[px, py, 10.0] for px, py in slots])
    states = [state(px, py, 1.0, f"uav{i + 1}") for i, (px, py) in enumerate(slots)]
    velocities = []
    for i, beh in enumerate(members):
        peers = [
            PeerReading(
                vehicle_id=f"uav{j + 1}",
                position_enu_m=(*slots[j], 10.0),
                true_g_m3=float(values[j]),
            )
            for j in range(3)
            if j != i
        ]
        # hovering: a 2 s window of the same readings, then the fit of their means
        for k in range(21):
            t = 1.0 + 0.1 * k
            sp = beh.step(
                state(*slots[i], t, f"uav{i + 1}"),
                states[:i] + states[i + 1 :],
                [reading(*slots[i], t, float(values[i]), peers)],
            )
        assert beh.gradient is not None
        assert sp is not None and sp.velocity_enu_m_s is not None
        velocities.append(sp.velocity_enu_m_s[:2])
    # In formation every member flies the same climb velocity: toward the axis and upwind.
    for v in velocities[1:]:
        assert v == pytest.approx(velocities[0], abs=1e-9)
    vx, vy = velocities[0]
    assert math.hypot(vx, vy) == pytest.approx(2.0, rel=1e-6)
    assert vy < 0.0  # y = 3 m: the axis is toward −y


def test_the_swarm_fits_its_peers_sensor_outputs_not_their_true_values() -> None:
    """With a lagging sensor (time constant 1 s) a peer sensor switched on in gas reads 0
    (clean air) at its first sample, true × (1 − e^(−0.5)) 0.5 s later and true × (1 − e^(−1))
    1 s later: the member's fit must use those, as its own reading does, not the true value."""
    lagging = msgspec.structs.replace(
        IDEAL, sensor=Sensor(preset="ideal", time_constant_s=1.0, period_ticks=10)
    )
    member = GradientSwarm(ctx(0, scenario=lagging))
    peer = PeerReading(vehicle_id="uav2", position_enu_m=(40.0, 0.0, 10.0), true_g_m3=0.8)
    assert member.peer_output(peer, 1.0) == 0.0
    assert member.peer_output(peer, 1.5) == pytest.approx(0.8 * -math.expm1(-0.5), rel=1e-12)
    # a checkpoint keeps the peers' sensor memory: the restored member goes on the same
    twin = GradientSwarm(ctx(0, scenario=lagging))
    twin.restore(member.checkpoint())
    third = member.peer_output(peer, 2.0)
    assert third == pytest.approx(0.8 * -math.expm1(-1.0), rel=1e-12)
    assert twin.peer_output(peer, 2.0) == third


# ---------------------------------------------------------------- casting and surge-cast
def fly_kinematic(
    beh, x: float, y: float, t: float, until_s: float, dt: float = 0.05, field=None, z=10.0
):
    """Follow the behaviour's velocity setpoints, the altitude's too, in ``field(x, y, z)``
    (clean air if None) until it declares or ``until_s``."""
    while t < until_s:
        value = 0.0 if field is None else field(x, y, z)
        seen = noiseless_reading("uav1", t, (x, y, z), value)
        sp = beh.step(state(x, y, t, z=z), [], [seen])
        if beh.declaration is not None:
            break
        vx, vy, vz = velocity(sp)
        x, y, z, t = x + vx * dt, y + vy * dt, z + vz * dt, t + dt
    return x, y, t


def test_surge_cast_keeps_surging_through_blanks_shorter_than_the_hit_memory() -> None:
    beh = SurgeCast(ctx())
    sp = beh.step(state(50.0, 5.0, 0.0), [], [])
    assert beh.state == "search"
    vx, vy, _ = velocity(sp)
    assert vx == pytest.approx(0.0, abs=1e-12) and abs(vy) == pytest.approx(2.5)  # crosswind
    sp = beh.step(state(50.0, 5.0, 1.0), [], [reading(50.0, 5.0, 1.0, 0.002)])
    assert beh.state == "surge"
    assert velocity(sp)[:2] == pytest.approx((-2.0, 0.0))  # straight upwind (wind toward +x)
    for t in (1.5, 2.5, 2.95):  # a 1.95 s blank: within the 2 s hit memory
        beh.step(state(50.0 - 2.0 * (t - 1.0), 5.0, t), [], [reading(0.0, 5.0, t, 0.0)])
        assert beh.state == "surge"
    sp = beh.step(state(45.8, 5.0, 3.1), [], [reading(45.8, 5.0, 3.1, 0.0)])
    # lost: back downwind (no drift while casting) to the line 1.5 m upwind of the only hit
    assert beh.state == "back"
    assert velocity(sp)[:2] == pytest.approx((2.0, 0.0))
    assert beh.declaration is None


def test_a_first_strong_whiff_is_never_a_declaration() -> None:
    """A filament peak 500x the threshold at first contact, then nothing: the old rule
    (strongest reading, lost twice) would declare; the evidence rule needs 10 detections."""
    for beh in (SurgeCast(ctx()), Casting(ctx())):
        beh.step(state(40.0, 0.0, 0.0), [], [reading(40.0, 0.0, 0.0, 0.5)])
        beh.step(state(39.9, 0.0, 0.05), [], [reading(39.9, 0.0, 0.05, 0.001)])
        fly_kinematic(beh, 39.8, 0.0, 0.1, until_s=200.0)
        assert beh.declaration is None, type(beh).__name__


def test_surge_cast_declares_between_the_frontier_and_an_empty_cast_line() -> None:
    """Hits every 0.1 s surging up the axis from x = 20 to x = 2 m (the frontier), then
    nothing. Back downwind to the line x = 2 - 1.5 = 0.5 m, a cast of eight legs there
    (half-widths 3, 4.8, 7.68, 12.288, 19.66, then the 20 m cap: 3 + 7.8 + 12.48 + 19.968 +
    31.949 + 39.661 + 40 + 40 = 194.86 m at 2.5 m/s = 77.94 s) with no hit, then the source is
    declared at the midpoint of the frontier and the line: (1.25, 0)."""
    beh = SurgeCast(ctx())
    t = 0.0
    for k in range(10):
        x = 20.0 - 2.0 * k
        beh.step(state(x, 0.0, t), [], [reading(x, 0.0, t, 0.01)])
        t += 0.1
    x = 2.0
    while beh.state == "surge":  # the memory runs out 4 m upwind of the last hit
        x -= 2.0 * 0.05
        t += 0.05
        beh.step(state(x, 0.0, t), [], [reading(x, 0.0, t, 0.0)])
    assert beh.state == "back"
    while beh.state == "back":
        x += 2.0 * 0.05
        t += 0.05
        beh.step(state(x, 0.0, t), [], [reading(x, 0.0, t, 0.0)])
    assert beh.state == "cast" and x == pytest.approx(0.5, abs=0.11)
    cast_start = t
    _, _, t_end = fly_kinematic(beh, x, 0.0, t, until_s=t + 120.0)
    assert beh.declaration is not None
    assert (beh.declaration.x_m, beh.declaration.y_m) == pytest.approx((1.25, 0.0), abs=1e-9)
    # each of the eight turns comes up to one 0.05 s step (0.125 m) late: out and back 0.1 s
    assert 194.86 / 2.5 <= t_end - cast_start + 0.05 <= 194.86 / 2.5 + 8 * 0.1 + 0.05


@pytest.mark.parametrize("cls", [SurgeCast, Casting])
def test_the_search_in_height_follows_a_plume_released_above_the_search_altitude(cls) -> None:
    """Gas within 1 m of the axis (wind toward +x) and within 0.2·x of the release height
    13 m, from x = 1 m: at the search altitude, 3 m below the release, it reaches only from
    x = 15 m. Held at its altitude, the searcher loses the plume there and declares between
    that frontier and its cast line, > 10 m from the source; searching in height, a cast leg
    1.5 m up meets the gas further upwind, and again, until the frontier is the release
    itself (x = 1 m): the declaration, at most 0.75 m from the frontier along the wind, is
    within 2 m of the source at the origin."""

    def field(x: float, y: float, z: float) -> float:
        return 0.01 if x >= 1.0 and abs(y) <= 1.0 and abs(z - 13.0) <= 0.2 * x else 0.0

    at_one = cls(ctx())
    fly_kinematic(at_one, 30.0, 0.0, 0.0, until_s=600.0, field=field)
    level = at_one.declaration
    assert level is not None and math.hypot(level.x_m, level.y_m) > 10.0
    searcher = type("InHeight", (cls,), {"vertical_step_m": 1.5})(ctx())
    fly_kinematic(searcher, 30.0, 0.0, 0.0, until_s=600.0, field=field)
    found = searcher.declaration
    assert found is not None and math.hypot(found.x_m, found.y_m) <= 2.0, found
    assert searcher.track_altitude_m == pytest.approx(13.0, abs=1.0)


def test_the_search_in_height_never_flies_below_its_floor() -> None:
    """A search started at 3 m with steps of 1.5 m: its legs' offsets 0, +1.5, −1.5, +3, −3,
    … reach 3 − 4.5 = −1.5 m, under the ground; the floor holds them at 1 m. In clean air
    the search's legs alternate sides: 200 s of them cover every offset."""
    beh = type("Low", (SurgeCast,), {"vertical_step_m": 1.5})(ctx())
    y = t = 0.0
    altitudes = set()
    while t < 200.0:
        sp = beh.step(state(40.0, y, t, z=3.0), [], [reading(40.0, y, t, 0.0)])
        altitudes.add(beh.flight_altitude())
        y, t = y + velocity(sp)[1] * 0.05, t + 0.05
    assert min(altitudes) == 1.0 and max(altitudes) == 3.0 + 3 * 1.5


def test_the_search_before_the_first_detection_widens_to_its_own_cap() -> None:
    """In clean air the sweep's half-widths grow ×1.6 from 3 m: 3, 4.8, 7.68, 12.29, 19.66,
    then the cap: 20 m by default; with a 60 m search cap 31.46 and 50.33 before it, so 200 s
    of legs at 2.5 m/s (≈ 900 m of legs from ±3 m) reach beyond ±50 m of the start."""

    def widest(beh) -> float:
        y = t = far = 0.0
        while t < 200.0:
            _, vy, _ = velocity(beh.step(state(40.0, y, t), [], [reading(40.0, y, t, 0.0)]))
            y, t = y + vy * 0.05, t + 0.05
            far = max(far, abs(y))
        return far

    assert widest(SurgeCast(ctx())) <= 20.0 + 0.125 + 1e-9  # a turn comes ≤ one step late
    wide = type("Wide", (SurgeCast,), {"max_search_half_width_m": 60.0})(ctx())
    assert 50.33 <= widest(wide) <= 60.0 + 0.125 + 1e-9


def test_casting_weaves_upwind_on_a_hit() -> None:
    beh = Casting(ctx())
    sp = beh.step(state(30.0, 0.0, 0.0), [], [reading(30.0, 0.0, 0.0, 0.01)])
    vx, vy, _ = velocity(sp)
    assert vx == pytest.approx(-Casting.surge_speed_m_s)  # surging upwind
    assert abs(vy) == pytest.approx(Casting.weave_speed_m_s)  # weaving across


def test_the_averaged_wind_is_an_exponential_average() -> None:
    """A step from calm to 6 m/s: after t the average is 6 (1 - exp(-t / 3 s))."""
    avg = AveragedWind(3.0)
    avg.add((0.0, 0.0), 0.0)
    for k in range(1, 31):
        avg.add((6.0, 0.0), 0.1 * k)
    assert avg.average is not None
    assert avg.average[0] == pytest.approx(6.0 * -math.expm1(-1.0), rel=1e-12)
    assert avg.mean().speed_m_s == pytest.approx(6.0 * 30 / 31, rel=1e-12)


# ---------------------------------------------------------------- oracle
def test_the_oracle_flies_straight_to_the_true_source_and_declares_it() -> None:
    beh = Oracle(ctx())  # novak2018: the source at the origin
    x, y, t = 40.0, 9.0, 0.0
    while t < 60.0:
        sp = beh.step(state(x, y, t), [], [])
        if beh.declaration is not None:
            break
        vx, vy, _ = velocity(sp)
        assert vx * 9.0 - vy * 40.0 == pytest.approx(0.0, abs=1e-9)  # along the line to it
        x, y, t = x + vx * 0.05, y + vy * 0.05, t + 0.05
    assert beh.declaration is not None
    assert (beh.declaration.x_m, beh.declaration.y_m) == (0.0, 0.0)
    # speed min(2 m/s, distance per second): 2 m/s to the last 2 m, then an exponential
    # approach with a 1 s time constant down to 0.5 m (ln 4 s)
    assert t == pytest.approx((math.hypot(40.0, 9.0) - 2.0) / 2.0 + math.log(4.0), abs=0.1)


# ---------------------------------------------------------------- random walk
def test_random_walk_statistics_match_a_run_and_tumble_walk() -> None:
    dt, steps, walkers = 0.1, 300, 600
    tau, v = RandomWalk.mean_run_s, RandomWalk.speed_m_s
    finals = []
    for w in range(walkers):
        beh = RandomWalk(ctx(seed=1000 + w, dt=dt))
        x = y = 0.0
        for k in range(steps):
            sp = beh.step(state(x, y, k * dt), [], [])
            vx, vy, _ = velocity(sp)
            assert math.hypot(vx, vy) == pytest.approx(v)
            x += vx * dt
            y += vy * dt
        finals.append((x, y))
    arr = np.array(finals)
    msd = float((arr**2).sum(axis=1).mean())
    # Heading kept each tick with probability p = exp(−dt/τ), else redrawn uniformly, so
    # <v_i·v_j> = v² p^|i−j| and MSD = v²dt² [n + 2 Σ_{k=1}^{n−1} (n − k) p^k].
    p = math.exp(-dt / tau)
    expected = v * v * dt * dt * (steps + 2 * sum((steps - k) * p**k for k in range(1, steps)))
    assert msd == pytest.approx(expected, rel=0.12)  # ≈ 3 standard errors with 600 walkers
    se = math.sqrt(expected / 2 / walkers)
    assert abs(arr[:, 0].mean()) < 4 * se and abs(arr[:, 1].mean()) < 4 * se
    assert RandomWalk(ctx(seed=3)).heading_rad == RandomWalk(ctx(seed=3)).heading_rad


# ---------------------------------------------------------------- detection with a slow sensor
MOX = msgspec.structs.replace(IDEAL, sensor=Sensor(preset="mox-tgs2620", period_ticks=12))
PID = msgspec.structs.replace(IDEAL, sensor=Sensor(preset="pid", period_ticks=12))


def _burst_hits(detector: PlumeDetector, bursts_at_s: tuple[float, ...]) -> list[float]:
    """A metal-oxide sensor sampled at 10 Hz for 150 s in clean air but for one 0.1 s sample
    of 65 g/m³ (a filament's peak) at each of ``bursts_at_s``; when ``detector`` hits."""
    sensor = ConcentrationSensor.for_vehicle(MOX, 0)
    hits = []
    for k in range(1500):
        t = 0.1 * k
        true = 65.0 if any(abs(t - b) < 1e-9 for b in bursts_at_s) else 0.0
        if detector.hit(sensor.sample(true, t)):
            hits.append(round(t, 1))
    return hits


def test_a_rise_detector_sees_each_burst_of_a_slow_sensor_once() -> None:
    """The metal-oxide preset (rise 2.96 s, decay 15.71 s): one burst lifts the reading by
    ≈ 65 × (1 − e^(−0.1/2.96)) ≈ 2.2 g/m³, and the decay keeps it above 0.001 g/m³ for
    15.71 × ln(2.2 / 0.001) ≈ 120 s: a level detector is still "in the plume" a minute later,
    while the rise detector hits on the burst samples only."""
    level = _burst_hits(PlumeDetector("level", PLUME_THRESHOLD_G_M3), (10.0, 90.0))
    assert level[0] == 10.0 and 70.0 in level and 89.9 in level  # a minute later: still "gas"
    detector = detector_for(ctx(scenario=MOX))
    # the rise a sensor in clean air shows in one 0.1 s sample on meeting 0.001 g/m³
    assert detector.mode == "rise"
    assert detector.threshold_g_m3 == pytest.approx(0.001 * (1 - math.exp(-0.1 / 2.96)))
    assert _burst_hits(detector, (10.0, 90.0)) == [10.0, 90.0]
    # an ideal sensor keeps the level
    assert detector_for(ctx()).mode == "level"


def test_source_seekers_use_the_rise_detector_with_a_lagging_sensor() -> None:
    for cls in (Casting, SurgeCast, Infotaxis):
        assert cls(ctx(scenario=MOX)).detector.mode == "rise", cls
        assert cls(ctx(scenario=PID)).detector.mode == "rise", cls
        assert cls(ctx()).detector.mode == "level", cls


# ---------------------------------------------------------------- detection above the noise
# The MiniPID's datasheet detection limit, 0.1 ppm of isobutylene (C4H8, 56.106 g/mol), in g/m³
# at 298.15 K and 1 atm (molar volume 8.314462618 × 298.15 / 101325 m³/mol), and its noise std
# (the limit taken as 3 × the std).
PID_FLOOR_G_M3 = 0.1e-6 * 56.106 / (8.314462618 * 298.15 / 101_325.0)
PID_NOISE_G_M3 = PID_FLOOR_G_M3 / 3.0


@pytest.mark.parametrize(
    ("preset", "floor_g_m3", "noise_g_m3", "mode", "threshold_g_m3"),
    [
        ("ideal", 0.0, 0.0, "level", PLUME_THRESHOLD_G_M3),
        ("novak2018", 0.01, 0.0, "level", 0.01),
        ("pid-fast", PID_FLOOR_G_M3, PID_NOISE_G_M3, "level", PLUME_THRESHOLD_G_M3),
        ("pid", PID_FLOOR_G_M3, PID_NOISE_G_M3, "rise", 3.0 * math.sqrt(2.0) * PID_NOISE_G_M3),
        ("mox-tgs2620", None, 0.0, "rise", 0.001 * (1 - math.exp(-0.1 / 2.96))),
    ],
)
def test_every_presets_detector_sits_above_its_floor_and_noise(
    preset: str, floor_g_m3: float | None, noise_g_m3: float, mode: str, threshold_g_m3: float
) -> None:
    """At a reading every 0.1 s. ideal: no lag, floor or noise — the level is 0.001 g/m³
    exactly (the behaviours' bits do not change). novak2018: no lag, its 0.01 g/m³ floor.
    pid-fast: τ 0.3 ms, 0.003 of the period, under the 1/20 that makes a sensor lag: a level;
    floor 2.29·10⁻⁴ g/m³ and 3σ = the floor, both below 0.001. pid: τ 1.3 s, 13 periods: a rise,
    its noise's 3·√2·σ = 3.2·10⁻⁴ g/m³ above the 0.001 × (1 − e^(−0.1/1.3)) = 7.4·10⁻⁵ a
    clean sensor shows in one sample on meeting 0.001 g/m³. mox (decay 15.71 s; no additive
    noise): the rise equivalent of 0.001 g/m³ — and every rise is to a reading at or above the
    floor (below it the output is 0)."""
    scenario = msgspec.structs.replace(IDEAL, sensor=Sensor(preset=preset, period_ticks=12))  # type: ignore[arg-type]
    sensor = ConcentrationSensor.for_vehicle(scenario, 0)
    if floor_g_m3 is not None:
        assert sensor.floor_g_m3 == pytest.approx(floor_g_m3, rel=1e-3, abs=1e-15)
    assert sensor.noise_std_g_m3 == pytest.approx(noise_g_m3, rel=1e-3, abs=1e-15)
    detector = detector_for(ctx(scenario=scenario))
    assert detector.mode == mode
    assert detector.threshold_g_m3 == pytest.approx(threshold_g_m3, rel=1e-3)
    if mode == "level":
        assert detector.threshold_g_m3 >= max(sensor.floor_g_m3, 3.0 * sensor.noise_std_g_m3)
    else:
        assert detector.threshold_g_m3 >= 3.0 * math.sqrt(2.0) * sensor.noise_std_g_m3
    if preset == "ideal":
        assert detector.threshold_g_m3 == PLUME_THRESHOLD_G_M3  # the same bits


def test_a_noisy_sensor_raises_the_detection_level_above_its_noise() -> None:
    """A fast PID with a noise std of 0.001 g/m³ (the level itself): clean air reads ≥ 0.001 g/m³
    in P(Z ≥ 1) ≈ 16 % of samples; the detector's level 3σ = 0.003 g/m³ lets noise through in
    P(Z ≥ 3) ≈ 0.13 % (20 000 samples: ≈ 27, the bound 100). A detection limit above 3σ wins."""
    noisy = msgspec.structs.replace(
        IDEAL, sensor=Sensor(preset="pid-fast", period_ticks=12, noise_std_g_m3=0.001)
    )
    detector = detector_for(ctx(scenario=noisy))
    assert (detector.mode, detector.threshold_g_m3) == ("level", pytest.approx(0.003))
    sensor = ConcentrationSensor.for_vehicle(noisy, 0)
    readings = [sensor.sample(0.0, 0.1 * k) for k in range(20_000)]
    naive = PlumeDetector("level", PLUME_THRESHOLD_G_M3)
    assert sum(naive.hit(r) for r in readings) > 0.1 * len(readings)
    assert sum(detector.hit(r) for r in readings) < 100
    limited = msgspec.structs.replace(
        noisy, sensor=Sensor(preset="pid-fast", period_ticks=12, noise_std_g_m3=0.001,
                             detection_limit_g_m3=0.005)
    )  # fmt: skip
    assert detector_for(ctx(scenario=limited)).threshold_g_m3 == pytest.approx(0.005)


# ---------------------------------------------------------------- detection with a lagging PID
PID_TAU_S = 1.30  # the MiniPID preset's time constant (rise = decay)


def _step_in_and_out(
    level_g_m3: float, in_s: float, out_s: float, tau_s: float, period_s: float, n: int
) -> list[tuple[float, float]]:
    """(t, reading) of a first-order sensor sampled every ``period_s`` from clean air, with
    ``level_g_m3`` of gas from ``in_s`` to ``out_s``: C·(1 − e^(−(t − in)/τ)) inside, then the
    value at ``out_s`` times e^(−(t − out)/τ)."""
    at_out = level_g_m3 * -math.expm1(-(out_s - in_s) / tau_s)
    series = []
    for k in range(n):
        t = k * period_s
        if t < in_s:
            value = 0.0
        elif t < out_s:
            value = level_g_m3 * -math.expm1(-(t - in_s) / tau_s)
        else:
            value = at_out * math.exp(-(t - out_s) / tau_s)
        series.append((t, value))
    return series


def test_a_rise_detector_sees_a_pid_enter_the_gas_and_not_its_decay() -> None:
    """The PID preset (τ 1.3 s) sampled at 10 Hz enters 0.05 g/m³ at 5 s and leaves at 15 s. Its
    output stays above 0.001 g/m³ for τ·ln(0.05 / 0.001) ≈ 5.1 s after it left, all of which a
    level detector calls gas; the rise detector hits from the first sample in the gas while the
    rise per sample, 0.05·(1 − e^(−0.1/τ))·e^(−k·0.1/τ), is ≥ its 3.2·10⁻⁴ g/m³ (k ≤ 31, the
    first 3.2 s), and never while the reading falls."""
    series = _step_in_and_out(0.05, 5.0, 15.0, PID_TAU_S, 0.1, 400)
    level = PlumeDetector("level", PLUME_THRESHOLD_G_M3)
    level_hits = [t for t, v in series if level.hit(v)]
    peak = 0.05 * -math.expm1(-10.0 / PID_TAU_S)
    last_level_s = 15.0 + PID_TAU_S * math.log(peak / PLUME_THRESHOLD_G_M3)
    assert max(level_hits) == pytest.approx(last_level_s, abs=0.1)  # ≈ 20.1 s: 5 s of decay
    detector = detector_for(ctx(scenario=PID))
    assert detector.mode == "rise"
    hits = [t for t, v in series if detector.hit(v)]
    threshold = 3.0 * math.sqrt(2.0) * PID_NOISE_G_M3
    first_rise = 0.05 * -math.expm1(-0.1 / PID_TAU_S)
    last_k = math.floor(PID_TAU_S / 0.1 * math.log(first_rise / threshold))
    assert hits[0] == pytest.approx(5.1)  # the first sample in the gas (5.0 still reads 0)
    assert hits[-1] == pytest.approx(5.1 + 0.1 * last_k)
    assert len(hits) == last_k + 1
    assert not [t for t in hits if t >= 15.0]  # none while it decays


def test_pid_noise_at_the_rise_threshold_hits_at_the_gaussian_tail_rate() -> None:
    """The PID preset held in a steady 0.01 g/m³ (43× its floor, so the output stage never
    clips) for 60 s, then 4 000 s more: the lag has settled (e^(−46)), every rise is the
    difference of two noise draws, std √2·σ, and the threshold 3·√2·σ is crossed with the
    one-sided Gaussian tail Q(3) = erfc(3/√2)/2 ≈ 0.135 % per sample: ≈ 54 of 40 000. Counts
    of rare exceedances are near Poisson; the bound is 4 standard deviations either side."""
    sensor = ConcentrationSensor.for_vehicle(PID, 0)
    detector = detector_for(ctx(scenario=PID))
    settle, samples = 600, 40_000
    for k in range(settle):
        detector.hit(sensor.sample(0.01, 0.1 * k))
    hits = sum(detector.hit(sensor.sample(0.01, 0.1 * k)) for k in range(settle, settle + samples))
    expected = samples * 0.5 * math.erfc(3.0 / math.sqrt(2.0))
    assert abs(hits - expected) <= 4.0 * math.sqrt(expected), (hits, expected)


def test_a_pid_decaying_through_its_floor_in_clean_air_makes_no_rise() -> None:
    """The PID preset meets a strong filament (1 g/m³ for 0.2 s) every 30 s, then clean air: its
    output decays for 30 s, through the floor (2.29·10⁻⁴ g/m³) after τ·ln(peak / floor) ≈ 7 s.
    In clean air a first-order output only falls, so every rise after the first sample out of
    the gas is noise. Just under the floor the output reads 0; a noise draw lifts the next
    sample just over it, a jump from 0 of the floor's size (more than the 3·√2·σ threshold,
    3.2·10⁻⁴ g/m³, whenever the output is within σ of the floor). Measured from the floor, the
    output d·σ above the floor gives a false rise with Φ(−d)·Q(3·√2 − d) ≤ 2.9·10⁻⁴ per sample
    (d = 2.12) while it decays from 3σ above the floor to it (τ·ln 2 ≈ 9 samples a tail), and
    with Q(4.24) ≈ 1.1·10⁻⁵ below: about 1 expected in 200 tails of 300 samples (bound 5).
    Measured from 0 it hit in many."""
    sensor = ConcentrationSensor.for_vehicle(PID, 0)
    detector = detector_for(ctx(scenario=PID))
    from_zero = PlumeDetector("rise", detector.threshold_g_m3)
    false_hits = false_from_zero = 0
    t = 0.0
    for _ in range(200):
        for k in range(302):
            value = sensor.sample(1.0 if k < 2 else 0.0, t)
            t += 0.1
            hit, naive = detector.hit(value), from_zero.hit(value)
            if k >= 3:  # out of the gas: the output only falls
                false_hits += hit
                false_from_zero += naive
    assert false_hits <= 5, false_hits
    assert false_from_zero > 20, false_from_zero  # what the floor's 0 did


@pytest.mark.parametrize(("tau_s", "mode"), [(0.004, "level"), (0.006, "rise"), (0.4, "rise")])
def test_a_lag_of_a_twentieth_of_the_sample_period_gets_the_rise_detector(
    tau_s: float, mode: str
) -> None:
    """A linear sensor read every 0.1 s (12 ticks at 120 Hz) lags from τ = 0.1 / 20 = 5 ms on."""
    scenario = msgspec.structs.replace(IDEAL, sensor=Sensor(time_constant_s=tau_s, period_ticks=12))
    assert detector_for(ctx(scenario=scenario)).mode == mode
    assert lags(scenario.sensor, 120.0) is (mode == "rise")


def test_infotaxis_flies_its_published_episode_again_field_for_field() -> None:
    """Run 0 of infotaxis in meander_low (the filament plume; a declaration after 191 s), test
    seed 0, ideal sensor, as results/gsl-ideal/runs.csv has it: every field of the line."""
    published, new = published_and_reflown("gsl-ideal", "infotaxis", "meander_low", 1)
    assert len(published) == 1
    assert new == published


def test_the_anchored_sweep_flies_the_same_wherever_the_scene_is() -> None:
    """A search in clean air under a 1 m/s wind whose direction swings ±0.6 rad with a 60 s
    period, from a start and from the same start 583 m away: measured from the point where
    it began, the anchored sweep's legs are the same (the wind and the sweep are the same
    relative to the start). Measured from the ENU origin, a turn of the frame by θ moves the
    sweep by |start|·θ, so the two flights part by metres."""

    def turning(own: VehicleState) -> tuple[float, float]:
        angle = 0.6 * math.sin(2.0 * math.pi * own.sim_time_s / 60.0)
        return math.sin(angle), math.cos(angle)  # toward north, swinging east and west

    def track(cls, x0: float, y0: float) -> list[tuple[float, float]]:
        beh = cls(ctx())
        beh.read_wind = turning
        x, y, t, out = x0, y0, 0.0, []
        while t < 120.0:
            vx, vy, _ = velocity(beh.step(state(x, y, t), [], [reading(x, y, t, 0.0)]))
            x, y, t = x + vx * 0.05, y + vy * 0.05, t + 0.05
            out.append((x - x0, y - y0))
        return out

    def parting(cls) -> float:
        near, far = track(cls, 6.0, 27.0), track(cls, 506.0, -273.0)
        return max(math.hypot(a[0] - b[0], a[1] - b[1]) for a, b in zip(near, far, strict=True))

    assert parting(type("Anchored", (SurgeCast,), {"sweep_about_anchor": True})) < 1e-6
    assert parting(SurgeCast) > 1.0  # the shift is one the origin's frame does not survive
