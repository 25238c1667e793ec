"""Randomised environment families: an environment file whose ``[randomise]`` table makes every
episode draw its own source, wind, release and atmosphere, and its own start and time limit.

A family file is a scenario file (the base: plume model, calibration, filaments, sensor) with
a ``[randomise]`` table of ranges (:class:`Family`). Episode (seed, run) draws, from its own
generator (``SeedSequence([seed, run, FAMILY_SALT])``, in the order of :class:`Draw`'s fields):

- the source position, uniform in ``source_x_m`` × ``source_y_m``;
- the wind: from-direction uniform in ``wind_from_deg``, speed uniform in ``wind_speed_m_s``;
- the release rate, log-uniform in ``release_rate_g_s``;
- the release height, the search altitude (10 m) plus a uniform ``release_height_offset_m``;
- the Pasquill class, uniform over ``stability``;
- the start: whether it is a crosswind start (probability ``crosswind_fraction``), its
  distance from the source (uniform in ``start_distance_m``) and its bearing off the downwind
  direction: uniform in ±``start_sector_deg`` (a downwind start), or uniform in
  ``crosswind_sector_deg`` on a side drawn with equal odds (a crosswind start, beside the
  plume: far more than 3 σy from its time-averaged axis).

The drawn scenario (:meth:`Family.scenario`) is the base with that source and wind, its
filaments living ``plume_length_m`` / u, calibrated by :func:`swarmbus.scenario.calibrate_scenario`
as every calibrated environment is (the time average has the drawn class's σy and σz). The
episode's limit (:meth:`Draw.time_limit_s`) is ``time_limit_multiple`` × the straight-flight
time from the start to the source at the search speed ``SEARCH_SPEED_M_S`` (the oracle's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import msgspec
import numpy as np

from swarmbus.errors import PlumeswarmError
from swarmbus.scenario import FAMILY_TABLE, Scenario, calibrate_scenario

#: Mixed into every draw's seed sequence (the starts of fixed environments use another).
FAMILY_SALT = 0xFA417
#: The flight altitude the release height is drawn around (the protocol's start altitude).
SEARCH_ALTITUDE_M = 10.0
#: The straight-flight speed a time limit is a multiple of: the oracle's, the informed
#: strategies' search speed (agents.behaviors.oracle).
SEARCH_SPEED_M_S = 2.0
#: The multiple ``--time-limit auto`` gives a fixed environment.
AUTO_TIME_LIMIT_MULTIPLE = 10.0


class FamilyError(PlumeswarmError, ValueError):
    """A bad ``[randomise]`` table: one line naming the key, its value and what is valid."""


Range = tuple[float, float]


@dataclass(frozen=True)
class Family:
    """The ranges of a ``[randomise]`` table (every key optional; these are the defaults)."""

    source_x_m: Range = (-50.0, 50.0)
    source_y_m: Range = (-50.0, 50.0)
    wind_from_deg: Range = (0.0, 360.0)
    wind_speed_m_s: Range = (2.0, 8.0)
    release_rate_g_s: Range = (3.0, 30.0)  # log-uniform
    release_height_offset_m: Range = (-5.0, 5.0)  # about SEARCH_ALTITUDE_M
    stability: tuple[str, ...] = ("B", "C", "D", "E")
    start_distance_m: Range = (30.0, 80.0)
    start_sector_deg: float = 20.0  # a downwind start: within ± this of the downwind direction
    crosswind_fraction: float = 0.25
    crosswind_sector_deg: Range = (60.0, 90.0)  # a crosswind start: this far off downwind
    plume_length_m: float = 120.0  # the filaments live plume_length_m / u
    time_limit_multiple: float = 10.0

    @classmethod
    def from_table(cls, table: Any, source: str) -> Family:
        """The family of a ``[randomise]`` table; :class:`FamilyError` names a bad key."""
        if not isinstance(table, dict):
            raise FamilyError(f"{source}: [{FAMILY_TABLE}] must be a table")
        known = {f.name: f for f in fields(cls)}
        values: dict[str, Any] = {}
        for key, value in table.items():
            where = f"{source}: {FAMILY_TABLE}.{key}"
            if key not in known:
                raise FamilyError(f"{where}: unknown key; valid: {', '.join(known)}")
            default = getattr(cls, key)
            if key == "stability":
                if (
                    not isinstance(value, list)
                    or not value
                    or not all(v in ("A", "B", "C", "D", "E", "F") for v in value)
                ):
                    raise FamilyError(f"{where} = {value!r}: a list of classes A–F")
                values[key] = tuple(value)
            elif isinstance(default, tuple):
                ok = isinstance(value, list) and len(value) == 2
                if not ok or not all(isinstance(v, int | float) for v in value):
                    raise FamilyError(f"{where} = {value!r}: expected [low, high]")
                if value[0] > value[1]:
                    raise FamilyError(f"{where} = {value!r}: low above high")
                values[key] = (float(value[0]), float(value[1]))
            else:
                if not isinstance(value, int | float) or isinstance(value, bool):
                    raise FamilyError(f"{where} = {value!r}: expected a number")
                values[key] = float(value)
        family = cls(**values)
        family._check(source)
        return family

    def _check(self, source: str) -> None:
        def bad(key: str, value: object, valid: str) -> FamilyError:
            return FamilyError(f"{source}: {FAMILY_TABLE}.{key} = {value!r}: {valid}")

        if self.wind_speed_m_s[0] <= 0.0:
            raise bad("wind_speed_m_s", list(self.wind_speed_m_s), "speeds must be > 0")
        if self.release_rate_g_s[0] <= 0.0:
            raise bad("release_rate_g_s", list(self.release_rate_g_s), "rates must be > 0")
        if SEARCH_ALTITUDE_M + self.release_height_offset_m[0] <= 0.0:
            raise bad("release_height_offset_m", list(self.release_height_offset_m), "above 0 m")
        if self.start_distance_m[0] <= 0.0:
            raise bad("start_distance_m", list(self.start_distance_m), "distances must be > 0")
        if not 0.0 <= self.crosswind_fraction <= 1.0:
            raise bad("crosswind_fraction", self.crosswind_fraction, "in [0, 1]")
        for key in ("plume_length_m", "time_limit_multiple"):
            if getattr(self, key) <= 0.0:
                raise bad(key, getattr(self, key), "must be > 0")

    def draw(self, seed: int, run: int) -> Draw:
        """Episode (seed, run)'s draw: the same numbers every time."""
        rng = np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, run, FAMILY_SALT])))
        x = float(rng.uniform(*self.source_x_m))
        y = float(rng.uniform(*self.source_y_m))
        from_deg = float(rng.uniform(*self.wind_from_deg))
        speed = float(rng.uniform(*self.wind_speed_m_s))
        lo, hi = self.release_rate_g_s
        rate = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
        height = SEARCH_ALTITUDE_M + float(rng.uniform(*self.release_height_offset_m))
        stability = self.stability[int(rng.integers(len(self.stability)))]
        crosswind = bool(rng.random() < self.crosswind_fraction)
        distance = float(rng.uniform(*self.start_distance_m))
        if crosswind:
            side = 1.0 if rng.random() < 0.5 else -1.0
            bearing = side * float(rng.uniform(*self.crosswind_sector_deg))
        else:
            bearing = float(rng.uniform(-self.start_sector_deg, self.start_sector_deg))
        return Draw(
            x, y, from_deg % 360.0, speed, rate, height, stability, crosswind, distance, bearing,
            self.time_limit_multiple, self.plume_length_m,
        )  # fmt: skip

    def scenario(self, base: Scenario, seed: int, run: int) -> Scenario:
        """The base scenario with episode (seed, run)'s draw, calibrated."""
        return self.draw(seed, run).apply(base)


@dataclass(frozen=True)
class Draw:
    """One episode's draw (:meth:`Family.draw`)."""

    source_x_m: float
    source_y_m: float
    wind_from_deg: float
    wind_speed_m_s: float
    release_rate_g_s: float
    release_height_m: float
    stability: str
    crosswind_start: bool
    start_distance_m: float
    start_bearing_deg: float  # off the downwind direction, positive to its left
    time_limit_multiple: float
    plume_length_m: float

    @property
    def start_along_across_m(self) -> tuple[float, float]:
        """The start downwind of the source and to the left of the downwind direction."""
        b = math.radians(self.start_bearing_deg)
        return self.start_distance_m * math.cos(b), self.start_distance_m * math.sin(b)

    @property
    def time_limit_s(self) -> float:
        """``time_limit_multiple`` × the straight flight from the start to the source."""
        return straight_flight_limit_s(self.start_distance_m, self.time_limit_multiple)

    def apply(self, base: Scenario) -> Scenario:
        """``base`` with this draw's source (the first; any others keep their offsets from
        it), wind and class, its filaments (or puffs) living ``plume_length_m`` / u,
        calibrated."""
        first = base.plume.sources[0]
        dx, dy = self.source_x_m - first.x_m, self.source_y_m - first.y_m
        sources = [
            msgspec.structs.replace(
                s,
                x_m=s.x_m + dx,
                y_m=s.y_m + dy,
                release_rate_g_s=self.release_rate_g_s,
                release_height_m=self.release_height_m,
            )
            for s in base.plume.sources
        ]
        age = self.plume_length_m / self.wind_speed_m_s
        plume = msgspec.structs.replace(
            base.plume,
            sources=sources,
            stability=self.stability,
            filament=msgspec.structs.replace(base.plume.filament, max_age_s=age),
            puff=msgspec.structs.replace(base.plume.puff, max_age_s=age),
        )
        wind = msgspec.structs.replace(
            base.wind, speed_m_s=self.wind_speed_m_s, from_deg=self.wind_from_deg
        )
        return calibrate_scenario(msgspec.structs.replace(base, plume=plume, wind=wind))


def straight_flight_limit_s(distance_m: float, multiple: float) -> float:
    """``multiple`` × the time to fly ``distance_m`` straight at ``SEARCH_SPEED_M_S``."""
    return multiple * distance_m / SEARCH_SPEED_M_S
