"""Plume field models and tools: the Gaussian plume, time-dependent filaments and puffs,
superposition, meshes and plots.

``from plume_service import GaussianPlume, FilamentPlume, PuffPlume, PlumeField`` is the public
surface; see docs/plume.md for the equations, conventions and guards.
"""

from plume_service.field import ConcentrationField, PlumeField
from plume_service.filament import FilamentPlume
from plume_service.gaussian import GaussianPlume
from plume_service.puff import PuffPlume

__all__ = ["ConcentrationField", "FilamentPlume", "GaussianPlume", "PlumeField", "PuffPlume"]
