"""Plume plots: the three PNGs exist and show something (not blank)."""

from __future__ import annotations

import numpy as np
from matplotlib.image import imread

from plume_service import GaussianPlume, PlumeField
from plume_service.plots import plot_all

EXPECTED = {"concentration_plan.png", "concentration_section.png", "crosswind_profile.png"}


def assert_non_blank_pngs(paths):
    assert {path.name for path in paths} == EXPECTED
    for path in paths:
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        pixels = imread(path)
        assert pixels.shape[0] > 200
        assert pixels.shape[1] > 200
        assert float(np.std(pixels[..., :3])) > 0.05, path.name


def test_plot_all_writes_non_blank_pngs(tmp_path):
    paths = plot_all(GaussianPlume.preset("novak2018"), tmp_path / "plots")
    assert_non_blank_pngs(paths)


def test_plot_all_at_ground_level_for_a_rotated_superposition(tmp_path):
    field = PlumeField(
        [
            GaussianPlume(10.0, 6.0, 10.0, wind_from_deg=200.0),
            GaussianPlume(4.0, 6.0, 5.0, wind_from_deg=200.0, source=(10.0, 0.0)),
        ]
    )
    paths = plot_all(field, tmp_path, height_m=0.0)
    assert_non_blank_pngs(paths)
