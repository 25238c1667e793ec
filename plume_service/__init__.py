"""Plume field model and tools: Gaussian plume science, superposition, meshes and plots.

``from plume_service import GaussianPlume, PlumeField`` is the public surface; see
docs/plume.md for the equations, conventions and guards.
"""

from plume_service.field import ConcentrationField, PlumeField
from plume_service.gaussian import GaussianPlume

__all__ = ["ConcentrationField", "GaussianPlume", "PlumeField"]
