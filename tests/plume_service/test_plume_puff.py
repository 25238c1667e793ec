"""Puff plume (CALPUFF-style): converges to the Gaussian plume in a steady wind, follows a wind
step, and carries the source's mass through a plane.

The Gaussian plume here is an independent closed form (Beychok's equation with the McMullen
class-D σ written out below from the published table), not the project's GaussianPlume.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pytest

from plume_atmosphere.wind import SteadyWind, WindModel, wind_model, wind_vector_enu
from plume_service.from_scenario import field_from_scenario
from plume_service.puff import PuffPlume
from swarmbus.scenario import PlumePuff, Wind, parse_scenario

Q, U, H = 10.0, 6.0, 10.0


def _sigma(x: np.ndarray, i: float, j: float, k: float) -> np.ndarray:
    ln_x = np.log(x)
    return np.exp(i + j * ln_x + k * ln_x**2)


def _gaussian_plume(downwind: np.ndarray, crosswind: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Beychok's equation, McMullen (1975) class D: σy (−2.555, 1.0423, −0.0087),
    σz (−3.186, 1.1737, −0.0316)."""
    sy = _sigma(downwind, -2.555, 1.0423, -0.0087)
    sz = _sigma(downwind, -3.186, 1.1737, -0.0316)
    vertical = np.exp(-((z - H) ** 2) / (2 * sz**2)) + np.exp(-((z + H) ** 2) / (2 * sz**2))
    return Q / (2 * math.pi * U * sy * sz) * np.exp(-(crosswind**2) / (2 * sy**2)) * vertical


def _puffs(wind: WindModel, max_age_s: float = 600.0) -> PuffPlume:
    params = PlumePuff(release_period_s=0.5, step_s=0.1, max_age_s=max_age_s)
    return PuffPlume((0.0, 0.0, H), Q, params, wind, stability="D", coefficients="mcmullen")


POINTS = np.array(
    [[50.0, 0.0, 10.0], [100.0, 0.0, 10.0], [100.0, 5.0, 5.0], [500.0, 0.0, 10.0], [1000, 20, 0]]
)


def test_puffs_in_a_steady_wind_equal_the_gaussian_plume() -> None:
    plume = _puffs(SteadyWind(U, 270.0))
    expected = _gaussian_plume(POINTS[:, 0], POINTS[:, 1], POINTS[:, 2])
    for t in (250.0, 251.23):  # once the puffs have passed 1000 m (167 s)
        assert plume.concentration(POINTS, t) == pytest.approx(expected, rel=0.01)


class _WindStep(WindModel):
    """From 270° until ``at_s``, from 180° (toward +y) after: a test wind."""

    def __init__(self, at_s: float) -> None:
        self.at_s = at_s
        self.mean_enu_m_s = wind_vector_enu(U, 270.0)

    def velocity(self, points: npt.ArrayLike, t: float) -> np.ndarray:
        n = np.asarray(points).shape[0]
        vector = wind_vector_enu(U, 270.0 if t < self.at_s else 180.0)
        return np.tile(np.asarray(vector), (n, 1))


def test_after_a_wind_step_the_field_near_the_source_is_the_rotated_plume() -> None:
    plume = _puffs(_WindStep(at_s=100.0))
    # wind toward +y: downwind is y, crosswind is x
    points = np.array([[0.0, 50.0, 10.0], [0.0, 100.0, 10.0], [5.0, 100.0, 5.0]])
    before = plume.concentration(points, 99.0)
    assert before.max() < 1e-12  # they were crosswind, far off the old axis
    expected = _gaussian_plume(points[:, 1], points[:, 0], points[:, 2])
    after = plume.concentration(points, 100.0 + 100.0 / U + 20.0)  # transit time to 100 m + 20 s
    assert after == pytest.approx(expected, rel=0.01)


def test_flux_through_a_plane_is_the_release() -> None:
    """∫∫∫ C·u dy dz dt over the plane x = 50 m for T = 10 s is Q·T."""
    plume = _puffs(SteadyWind(U, 270.0), max_age_s=30.0)
    y = np.arange(-30.0, 30.0 + 1e-9, 1.0)
    z = np.arange(0.0, 40.0 + 1e-9, 1.0)
    yy, zz = np.meshgrid(y, z, indexing="ij")
    plane = np.column_stack([np.full(yy.size, 50.0), yy.ravel(), zz.ravel()])
    step = 0.1  # the model's internal step: the field is held in between
    total = 0.0
    for t in np.arange(60.0, 70.0 - 1e-9, step):
        c = plume.concentration(plane, t).reshape(yy.shape)
        total += U * np.trapezoid(np.trapezoid(c, z, axis=1), y) * step
    assert total == pytest.approx(Q * 10.0, rel=0.01)


def test_puff_scenario_builds_and_is_deterministic_after_going_back() -> None:
    scenario = parse_scenario(
        '[plume]\nmodel = "puff"\n[plume.puff]\nrelease_period_s = 1.0\n'
        '[wind]\nmodel = "meander"\n[[vehicles]]\nid = "a"\n'
    )
    field = field_from_scenario(scenario)
    assert isinstance(field, PuffPlume)
    late = field.concentration(POINTS[:3], 40.0)
    early = field.concentration(POINTS[:3], 12.0)
    again = field_from_scenario(scenario)
    assert again.concentration(POINTS[:3], 12.0).tobytes() == early.tobytes()
    assert again.concentration(POINTS[:3], 40.0).tobytes() == late.tobytes()
    assert late[0] > 0.0
    assert isinstance(wind_model(Wind(), 0), SteadyWind)
