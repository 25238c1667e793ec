"""Validation of the Gaussian plume model against values from outside the code under test.

Expected values come from published σ tables, hand arithmetic with the math module, exact
integrals (mass conservation), the analytic mixing-lid limit and the seed's measured window.
"""

from __future__ import annotations

import inspect
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from plume_service import ConcentrationField, GaussianPlume, PlumeField

# McMullen class D as published (Turner 1970 via McMullen 1975).
D_Y = (-2.555, 1.0423, -0.0087)
D_Z = (-3.186, 1.1737, -0.0316)
CLASSES = ("A", "B", "C", "D", "E", "F")
FAMILIES = ("mcmullen", "briggs-rural", "briggs-urban")
CONFIGS = [(s, f) for f in FAMILIES for s in CLASSES] + [("D", "novak2018")]


def mcmullen_sigma(coefficients: tuple[float, float, float], x: float) -> float:
    i, j, k = coefficients
    return math.exp(i + j * math.log(x) + k * math.log(x) ** 2)


def centreline(plume: GaussianPlume, xs: np.ndarray, z: float) -> np.ndarray:
    return plume.concentration(np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, z)]))


def crossing(plume: GaussianPlume, level: float, lo: float, hi: float, z: float) -> float:
    """Downwind distance where the decaying centreline at height z crosses ``level``."""
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if centreline(plume, np.array([mid]), z)[0] > level:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


# ---------------------------------------------------------------- published σ and hand checks


@pytest.mark.parametrize(("x", "sigma_y", "sigma_z"), [(100.0, 7.85, 4.71), (1000.0, 68.7, 30.4)])
def test_mcmullen_class_d_sigmas_match_published_values(x, sigma_y, sigma_z):
    plume = GaussianPlume(10.0, 6.0, 10.0)
    got_y, got_z = plume.sigmas(np.array([x]))
    assert got_y[0] == pytest.approx(sigma_y, rel=2e-3)
    assert got_z[0] == pytest.approx(sigma_z, rel=2e-3)


def test_briggs_rural_class_d_sigmas_at_one_km():
    # Briggs (1973) rural D: σy = 0.08x/√(1+0.0001x), σz = 0.06x/√(1+0.0015x) at x = 1000 m.
    plume = GaussianPlume(10.0, 6.0, 10.0, coefficients="briggs-rural")
    got_y, got_z = plume.sigmas(np.array([1000.0]))
    assert got_y[0] == pytest.approx(80.0 / math.sqrt(1.1), rel=1e-12)
    assert got_z[0] == pytest.approx(60.0 / math.sqrt(2.5), rel=1e-12)


def test_briggs_urban_class_a_sigmas_at_one_km():
    # Griffiths (1994) Table 1, urban A–B: σy = 0.32x/√(1+0.0004x), σz = 0.24x·√(1+0.001x).
    plume = GaussianPlume(10.0, 6.0, 10.0, stability="A", coefficients="briggs-urban")
    got_y, got_z = plume.sigmas(np.array([1000.0]))
    assert got_y[0] == pytest.approx(320.0 / math.sqrt(1.4), rel=1e-12)
    assert got_z[0] == pytest.approx(240.0 * math.sqrt(2.0), rel=1e-12)


def test_point_value_matches_hand_computed_beychok_equation():
    q, u, h = 10.0, 6.0, 10.0
    x, y, z = 250.0, 12.0, 4.0
    sy = mcmullen_sigma(D_Y, x)
    sz = mcmullen_sigma(D_Z, x)
    f = math.exp(-(y**2) / (2 * sy**2))
    g = math.exp(-((z - h) ** 2) / (2 * sz**2)) + math.exp(-((z + h) ** 2) / (2 * sz**2))
    expected = q / u * f / (sy * math.sqrt(2 * math.pi)) * g / (sz * math.sqrt(2 * math.pi))
    got = GaussianPlume(q, u, h).concentration(np.array([[x, y, z]]))
    assert got.dtype == np.float64
    assert got.shape == (1,)
    assert got[0] == pytest.approx(expected, rel=1e-12)


def test_novak2018_preset_is_the_seed_plume():
    plume = GaussianPlume.preset("novak2018")
    # Seed coefficients with K_z = +0.0316: σz(100 m) ≈ 18 m, not 4.7 m.
    _, sigma_z = plume.sigmas(np.array([100.0]))
    assert sigma_z[0] == pytest.approx(mcmullen_sigma((-3.186, 1.1737, 0.0316), 100.0), rel=1e-12)
    assert 17.5 < sigma_z[0] < 18.5
    info = plume.info()
    assert info["release_rate_g_s"] == 10.0
    assert info["release_height_m"] == 10.0
    assert info["wind"]["speed_m_s"] == 6.0
    assert info["stability"] == "D"
    assert info["source_m"] == [0.0, 0.0]


@pytest.mark.parametrize(
    ("preset", "coefficients", "near", "far"),
    [("novak2018", None, 14.1, 50.2), (None, "mcmullen", 17.6, 83.6)],
)
def test_sensor_window_on_the_centreline_matches_the_seed(preset, coefficients, near, far):
    # From the closed form: the [0.01, 0.2] g/m³ window holds at z = 10 m between these distances.
    if preset:
        plume = GaussianPlume.preset(preset)
    else:
        plume = GaussianPlume(10.0, 6.0, 10.0, coefficients=coefficients)
    assert crossing(plume, 0.2, 2.0, 200.0, 10.0) == pytest.approx(near, abs=0.1)
    assert crossing(plume, 0.01, 2.0, 500.0, 10.0) == pytest.approx(far, abs=0.1)


# ------------------------------------------------------------------------- conservation laws


def trapezoid(values, grid):
    """Trapezoid rule along the last axis (numpy-only; np.trapezoid needs numpy ≥ 2)."""
    widths = np.diff(grid)
    return np.sum(0.5 * (values[..., 1:] + values[..., :-1]) * widths, axis=-1)


def mass_flux(plume: GaussianPlume, x: float, z_top: float | None = None) -> float:
    """∬ u·C dy dz over the cross-section at downwind distance x (trapezoid, fine grid)."""
    sy, sz = (float(s[0]) for s in plume.sigmas(np.array([x])))
    ys = np.linspace(-9 * sy, 9 * sy, 721)
    top = z_top if z_top is not None else plume.release_height_m + 10 * sz
    zs = np.linspace(0.0, top, 1201)
    grid_y, grid_z = np.meshgrid(ys, zs, indexing="ij")
    points = np.column_stack([np.full(grid_y.size, x), grid_y.ravel(), grid_z.ravel()])
    c = plume.concentration(points).reshape(grid_y.shape)
    return plume.wind_speed_m_s * trapezoid(trapezoid(c, zs), ys)


@pytest.mark.parametrize("x", [50.0, 500.0])
@pytest.mark.parametrize(
    ("family", "stability"),
    [("mcmullen", "D"), ("mcmullen", "A"), ("briggs-rural", "F"), ("briggs-urban", "C")],
)
def test_mass_is_conserved_through_a_cross_section(x, family, stability):
    plume = GaussianPlume(7.0, 4.0, 10.0, stability=stability, coefficients=family)
    assert mass_flux(plume, x) == pytest.approx(7.0, rel=0.01)


@pytest.mark.parametrize("x", [500.0, 5000.0])  # σz < L (image sum) and σz > L (Fourier form)
def test_mass_is_conserved_under_a_mixing_lid(x):
    lid = 50.0
    plume = GaussianPlume(7.0, 4.0, 10.0, mixing_height=lid)
    assert mass_flux(plume, x, z_top=lid) == pytest.approx(7.0, rel=0.01)


@pytest.mark.parametrize("z", [0.0, 10.0, 55.0, 100.0])
def test_mixing_lid_far_field_tends_to_uniform_mixing(z):
    q, u, lid, x = 10.0, 6.0, 100.0, 20_000.0
    plume = GaussianPlume(q, u, 10.0, mixing_height=lid)
    expected = q / (math.sqrt(2 * math.pi) * mcmullen_sigma(D_Y, x) * lid * u)
    assert plume.concentration(np.array([[x, 0.0, z]]))[0] == pytest.approx(expected, rel=0.01)


def test_lid_formulas_agree_where_they_switch():
    plume = GaussianPlume(10.0, 6.0, 10.0)
    lid = float(plume.sigmas(np.array([1000.0]))[1][0])  # σz(1 km) = L: the switch point
    capped = GaussianPlume(10.0, 6.0, 10.0, mixing_height=lid)
    xs = np.array([1000.0 - 1e-6, 1000.0 + 1e-6])
    for z in (0.0, 10.0, lid / 2, lid):
        below, above = capped.concentration(np.column_stack([xs, [3.0, 3.0], [z, z]]))
        assert above == pytest.approx(below, rel=1e-8)


def test_nothing_above_the_lid_or_below_ground():
    plume = GaussianPlume(10.0, 6.0, 10.0, mixing_height=80.0)
    values = plume.concentration(np.array([[300.0, 0.0, 80.1], [300.0, 0.0, -0.1]]))
    assert values.tolist() == [0.0, 0.0]


# -------------------------------------------------------------------------------- geometry


def test_symmetric_across_the_wind():
    rng = np.random.default_rng(1)
    points = rng.uniform([0.0, -30.0, 0.0], [300.0, 30.0, 40.0], size=(2000, 3))
    mirrored = points * [1.0, -1.0, 1.0]
    plume = GaussianPlume(10.0, 6.0, 10.0)
    np.testing.assert_array_equal(plume.concentration(points), plume.concentration(mirrored))


@pytest.mark.parametrize("family", FAMILIES)
@pytest.mark.parametrize("stability", CLASSES)
@pytest.mark.parametrize("z", [0.0, 10.0])
def test_centreline_decays_monotonically_past_its_maximum(family, stability, z):
    plume = GaussianPlume(10.0, 6.0, 10.0, stability=stability, coefficients=family)
    xs = np.geomspace(0.5, 20_000.0, 3000)
    values = centreline(plume, xs, z)
    peak = int(np.argmax(values))
    assert values[peak] > 0
    assert np.all(np.diff(values[peak:]) <= 0.0)


@pytest.mark.parametrize(("stability", "family"), CONFIGS)
def test_sigmas_grow_monotonically_from_the_source(family, stability):
    plume = GaussianPlume(10.0, 6.0, 10.0, stability=stability, coefficients=family)
    xs = np.geomspace(1e-3, 1e7, 5000)
    for sigma in plume.sigmas(xs):
        assert np.all(sigma > 0)
        assert np.all(np.diff(sigma) >= 0.0)


def test_class_a_near_field_guard_is_continuous_and_linear():
    plume = GaussianPlume(10.0, 6.0, 10.0, stability="A")
    # The published class-A σz fit has its minimum at ln x = 1.7172 / (2·0.2770).
    x_turn = math.exp(1.7172 / (2 * 0.2770))
    sigma_turn = mcmullen_sigma((4.679, -1.7172, 0.2770), x_turn)
    _, sz = plume.sigmas(np.array([x_turn * (1 - 1e-9), x_turn * 0.5, 200.0]))
    assert sz[0] == pytest.approx(sigma_turn, rel=1e-6)
    assert sz[1] == pytest.approx(sigma_turn / 2, rel=1e-6)
    # Beyond the turn the published fit is used unchanged.
    assert sz[2] == pytest.approx(mcmullen_sigma((4.679, -1.7172, 0.2770), 200.0), rel=1e-12)


def test_superposition_of_two_sources_is_the_sum():
    a = GaussianPlume(10.0, 6.0, 10.0)
    b = GaussianPlume(3.0, 6.0, 25.0, stability="B", source=(40.0, -15.0), wind_from_deg=250.0)
    rng = np.random.default_rng(2)
    points = rng.uniform([-50.0, -80.0, 0.0], [400.0, 80.0, 60.0], size=(5000, 3))
    field = PlumeField([a, b])
    np.testing.assert_allclose(
        field.concentration(points), a.concentration(points) + b.concentration(points), rtol=1e-15
    )
    assert [s["release_rate_g_s"] for s in field.info()["sources"]] == [10.0, 3.0]


@pytest.mark.parametrize(
    ("wind_from_deg", "rotate"),
    [
        (180.0, lambda x, y: (-y, x)),  # toward north: downwind +y, left of the wind is −x
        (90.0, lambda x, y: (-x, -y)),  # toward west
        (0.0, lambda x, y: (y, -x)),  # toward south
    ],
)
def test_wind_direction_rotates_the_plume(wind_from_deg, rotate):
    rng = np.random.default_rng(3)
    points = rng.uniform([-20.0, -30.0, 0.0], [300.0, 30.0, 40.0], size=(3000, 3))
    east, north = rotate(points[:, 0], points[:, 1])
    rotated = np.column_stack([east, north, points[:, 2]])
    default = GaussianPlume(10.0, 6.0, 10.0)
    turned = GaussianPlume(10.0, 6.0, 10.0, wind_from_deg=wind_from_deg)
    np.testing.assert_allclose(
        turned.concentration(rotated), default.concentration(points), rtol=1e-12
    )


def test_oblique_wind_and_offset_source():
    plume = GaussianPlume(10.0, 6.0, 10.0, source=(100.0, -40.0), wind_from_deg=225.0)
    # Wind from the south-west blows toward the north-east; 100 m downwind on the axis:
    downwind = np.array([[100.0 + 100 / math.sqrt(2), -40.0 + 100 / math.sqrt(2), 10.0]])
    reference = GaussianPlume(10.0, 6.0, 10.0).concentration(np.array([[100.0, 0.0, 10.0]]))
    assert plume.concentration(downwind)[0] == pytest.approx(reference[0], rel=1e-12)


# ------------------------------------------------------------------------------------ guards


def test_upwind_and_at_the_source_is_exactly_zero():
    plume = GaussianPlume.preset("novak2018")
    points = np.array(
        [
            [0.0, 0.0, 10.0],
            [-1e-300, 0.0, 10.0],
            [-5.0, 0.0, 10.0],
            [-1e6, 3.0, 0.0],
            [0.0, 5.0, 0.0],
        ]
    )
    values = plume.concentration(points)
    assert values.tolist() == [0.0] * len(points)


def test_just_downwind_of_the_source_is_finite():
    plume = GaussianPlume(10.0, 6.0, 10.0, stability="A")
    values = plume.concentration(
        np.array([[1e-300, 0.0, 10.0], [1e-9, 0.0, 10.0], [1e-3, 1e-3, 10.0], [0.5, 0.0, 10.0]])
    )
    assert np.all(np.isfinite(values))
    assert np.all(values >= 0)


@pytest.mark.parametrize("wind_speed", [0.0, -1.0, math.nan, math.inf])
def test_wind_speed_must_be_positive_and_finite(wind_speed):
    with pytest.raises(ValueError, match=rf"wind_speed.*{wind_speed}"):
        GaussianPlume(10.0, wind_speed, 10.0)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"stability": "G"}, "stability"),
        ({"stability": "d"}, "stability"),
        ({"coefficients": "pasquill"}, "coefficients"),
        ({"coefficients": "novak2018", "stability": "B"}, "stability"),
        ({"release_rate": -1.0}, "release_rate"),
        ({"release_height": math.nan}, "release_height"),
        ({"mixing_height": 5.0}, "mixing_height"),
        ({"mixing_height": 0.0}, "mixing_height"),
        ({"source": (0.0, math.inf)}, r"source\[1\]"),
        ({"wind_from_deg": math.nan}, "wind_from_deg"),
    ],
)
def test_invalid_parameters_are_rejected_by_name(kwargs, name):
    arguments = {"release_rate": 10.0, "wind_speed": 6.0, "release_height": 10.0, **kwargs}
    with pytest.raises(ValueError, match=name):
        GaussianPlume(**arguments)


def test_unknown_preset_names_itself_and_the_valid_ones():
    with pytest.raises(ValueError, match=r"'novak2019'.*novak2018"):
        GaussianPlume.preset("novak2019")


@pytest.mark.parametrize(
    "points",
    [
        np.zeros(3),
        np.zeros((4, 2)),
        np.zeros((2, 3, 1)),
        np.array([[1.0, 2.0, math.nan]]),
        np.array([[1.0, math.inf, 2.0]]),
        [["a", "b", "c"]],
    ],
)
def test_malformed_points_are_rejected(points):
    with pytest.raises(ValueError, match="points"):
        GaussianPlume(10.0, 6.0, 10.0).concentration(points)


def test_empty_batch_and_list_input():
    plume = GaussianPlume(10.0, 6.0, 10.0)
    assert plume.concentration(np.empty((0, 3))).shape == (0,)
    assert plume.concentration([[100.0, 0.0, 10.0]])[0] > 0


def test_non_finite_time_is_rejected():
    with pytest.raises(ValueError, match="t must be finite"):
        GaussianPlume(10.0, 6.0, 10.0).concentration(np.zeros((1, 3)), t=math.nan)


def test_empty_superposition_is_rejected():
    with pytest.raises(ValueError, match="sources"):
        PlumeField([])


@settings(max_examples=60, deadline=None)
@given(
    config=st.sampled_from(CONFIGS),
    lid=st.one_of(st.none(), st.floats(20.0, 5000.0)),
    wind_from_deg=st.floats(-720.0, 720.0),
    points=st.lists(
        st.tuples(*[st.floats(-1e300, 1e300, allow_nan=False)] * 3), min_size=1, max_size=20
    ),
)
def test_any_finite_point_gives_a_finite_non_negative_value(config, lid, wind_from_deg, points):
    stability, family = config
    plume = GaussianPlume(
        10.0,
        3.0,
        15.0,
        stability=stability,
        coefficients=family,
        wind_from_deg=wind_from_deg,
        mixing_height=lid,
    )
    values = plume.concentration(np.array(points, dtype=np.float64))
    assert np.all(np.isfinite(values))
    assert np.all(values >= 0.0)


# ---------------------------------------------------------------------- chunks and interface


def test_large_batches_match_small_ones():
    # More points than one chunk, and enough to take the threaded path.
    rng = np.random.default_rng(4)
    points = rng.uniform([-10.0, -40.0, 0.0], [500.0, 40.0, 50.0], size=(600_000, 3))
    plume = GaussianPlume(10.0, 6.0, 10.0, mixing_height=60.0)
    whole = plume.concentration(points)
    pieces = np.concatenate([plume.concentration(part) for part in np.array_split(points, 37)])
    np.testing.assert_array_equal(whole, pieces)


@pytest.mark.parametrize("lid", [None, 60.0])
def test_sparse_and_dense_chunks_agree(lid):
    # A chunk mostly inside the plume is evaluated whole; one mostly outside only where needed.
    rng = np.random.default_rng(6)
    inside = rng.uniform([0.5, -40.0, 0.0], [500.0, 40.0, 50.0], size=(1000, 3))
    upwind = rng.uniform([-500.0, -40.0, 0.0], [0.0, 40.0, 50.0], size=(5000, 3))
    plume = GaussianPlume(10.0, 6.0, 10.0, mixing_height=lid)
    dense = plume.concentration(inside)
    sparse = plume.concentration(np.vstack([upwind[:2500], inside, upwind[2500:]]))
    np.testing.assert_array_equal(sparse[2500:3500], dense)
    assert not sparse[:2500].any()
    assert not sparse[3500:].any()


def test_to_plume_frame():
    plume = GaussianPlume(10.0, 6.0, 10.0, source=(5.0, 5.0), wind_from_deg=180.0)
    x, y, z = plume.to_plume_frame(np.array([[5.0, 25.0, 3.0], [2.0, 5.0, 1.0]]))
    assert x.tolist() == [20.0, 0.0]  # 20 m north is 20 m downwind of a southerly wind
    assert y.tolist() == [0.0, 3.0]  # 3 m west is to the left of a wind blowing north
    assert z.tolist() == [3.0, 1.0]


def test_info_is_plain_json():
    field = PlumeField([GaussianPlume.preset("novak2018"), GaussianPlume(1.0, 2.0, 3.0)])
    decoded = json.loads(json.dumps(field.info()))
    assert decoded["model"] == "superposition"
    assert decoded["sources"][0]["preset"] == "novak2018"
    assert decoded["sources"][0]["wind"]["from_deg"] == 270.0
    assert decoded["sources"][1]["coefficients"] == "mcmullen"


def test_public_surface_is_locked():
    parameters = inspect.signature(GaussianPlume).parameters
    assert list(parameters) == [
        "release_rate",
        "wind_speed",
        "release_height",
        "stability",
        "coefficients",
        "source",
        "wind_from_deg",
        "mixing_height",
    ]
    defaults = {name: p.default for name, p in parameters.items()}
    assert defaults["stability"] == "D"
    assert defaults["coefficients"] == "mcmullen"
    assert defaults["source"] == (0.0, 0.0)
    assert defaults["wind_from_deg"] == 270.0
    assert defaults["mixing_height"] is None
    assert issubclass(GaussianPlume, ConcentrationField)
    assert issubclass(PlumeField, ConcentrationField)
    assert list(inspect.signature(GaussianPlume.concentration).parameters) == [
        "self",
        "points",
        "t",
    ]
