"""Gases a sensor can report in ppm, and the ideal-gas conversion between g/m³ and ppm.

ppm here is a mole (= volume, for an ideal gas) fraction in parts per million:
``ppm = c / M · R·T / p · 10⁶`` for a mass concentration ``c`` in g/m³, the gas's molar mass
``M`` in g/mol, the air temperature ``T`` in K and pressure ``p`` in Pa.

Molar masses are computed from each gas's formula with the IUPAC conventional atomic weights
(Prohaska et al., "Standard atomic weights of the elements 2021", Pure Appl. Chem. 94 (2022)
573: H 1.008, C 12.011, N 14.007, O 15.999, F 18.998, S 32.06). The molar gas constant
is CODATA 2018's exact R = 8.314462618 J/(mol·K).
"""

from __future__ import annotations

import math

GAS_CONSTANT_J_MOL_K = 8.314462618

ATOMIC_WEIGHT_G_MOL: dict[str, float] = {
    "H": 1.008,
    "C": 12.011,
    "N": 14.007,
    "O": 15.999,
    "F": 18.998,
    "S": 32.06,
}

# name → formula as element counts
FORMULAS: dict[str, dict[str, int]] = {
    "methane": {"C": 1, "H": 4},
    "ethane": {"C": 2, "H": 6},
    "propane": {"C": 3, "H": 8},
    "butane": {"C": 4, "H": 10},
    "isobutylene": {"C": 4, "H": 8},  # the usual PID calibration gas
    "ethanol": {"C": 2, "H": 6, "O": 1},
    "acetone": {"C": 3, "H": 6, "O": 1},
    "hydrogen": {"H": 2},
    "carbon_monoxide": {"C": 1, "O": 1},
    "carbon_dioxide": {"C": 1, "O": 2},
    "ammonia": {"N": 1, "H": 3},
    "nitrogen_dioxide": {"N": 1, "O": 2},
    "hydrogen_sulfide": {"H": 2, "S": 1},
    "sulfur_dioxide": {"S": 1, "O": 2},
    "sulfur_hexafluoride": {"S": 1, "F": 6},  # the usual tracer gas of dispersion trials
}


def molar_mass_g_mol(gas: str) -> float:
    """The gas's molar mass; ``KeyError`` for a gas not in :data:`FORMULAS`."""
    return math.fsum(ATOMIC_WEIGHT_G_MOL[el] * n for el, n in FORMULAS[gas].items())


def ppm_per_g_m3(gas: str, temperature_k: float, pressure_pa: float) -> float:
    """ppm of ``gas`` that 1 g/m³ of it is at ``temperature_k`` and ``pressure_pa``."""
    return GAS_CONSTANT_J_MOL_K * temperature_k / pressure_pa / molar_mass_g_mol(gas) * 1e6
