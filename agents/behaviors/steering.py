"""Setpoints a source-seeking behaviour flies: velocity at an altitude, holding over a point,
heading for a point, and the crosswind sweep (the search pattern of casting, surge-cast and the
plume-less phases of the other strategies)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from agents.behavior import SourceEstimate
from agents.behavior_state import SavesState
from agents.behaviors.wind import WindFrame
from swarmbus.messages import Setpoint, VehicleState


def fly(
    own: VehicleState, velocity_en_m_s: tuple[float, float], altitude_m: float, gain: float = 1.0
) -> Setpoint:
    """A velocity setpoint: horizontal as given, vertical holding ``altitude_m``."""
    vz = gain * (altitude_m - own.position_enu_m[2])
    return Setpoint(velocity_enu_m_s=(velocity_en_m_s[0], velocity_en_m_s[1], vz))


def hold_at(x_m: float, y_m: float, altitude_m: float) -> Setpoint:
    """A position setpoint over a point at ``altitude_m`` (after a declaration)."""
    return Setpoint(position_enu_m=(x_m, y_m, altitude_m))


def start_or_hold(
    own: VehicleState, altitude_m: float | None, declaration: SourceEstimate | None
) -> tuple[float, Setpoint | None]:
    """The altitude a search flies at (the vehicle's own at its first step) and, once the
    source is declared, the setpoint that holds over the declaration."""
    altitude = own.position_enu_m[2] if altitude_m is None else altitude_m
    if declaration is None:
        return altitude, None
    return altitude, hold_at(declaration.x_m, declaration.y_m, altitude)


def toward(own: VehicleState, x_m: float, y_m: float, speed_m_s: float) -> tuple[float, float]:
    """Horizontal velocity toward (x, y) at ``speed_m_s``, slowing inside the last metre."""
    dx, dy = x_m - own.position_enu_m[0], y_m - own.position_enu_m[1]
    dist = math.hypot(dx, dy)
    if dist < 1e-9:
        return 0.0, 0.0
    speed = min(speed_m_s, dist)
    return speed * dx / dist, speed * dy / dist


@dataclass(eq=False)
class CrosswindSweep(SavesState):
    """Crosswind legs of growing width around an anchor line, drifting along the wind: the
    search pattern of casting, surge-cast and the plume-less phases of the other strategies.

    Each leg ends ``half_width_m`` from the anchor (the crosswind coordinate where the sweep
    began); at its end the vehicle turns and the half-width grows by ``growth`` up to
    ``max_half_width_m``. ``drift_m_s`` > 0 drifts downwind, < 0 upwind.
    """

    state_attributes = ("side", "anchor_across_m", "anchor_xy", "half_width_m", "legs")

    speed_m_s: float
    drift_m_s: float
    first_half_width_m: float
    growth: float
    max_half_width_m: float = 40.0
    side: float = 1.0
    about_anchor: bool = False  # across measured from the anchor point, not the ENU origin
    anchor_across_m: float | None = field(default=None, init=False)
    anchor_xy: tuple[float, float] | None = field(default=None, init=False)
    half_width_m: float = field(init=False)
    legs: int = field(default=0, init=False)  # legs completed (turns), over every sweep

    def __post_init__(self) -> None:
        self.half_width_m = self.first_half_width_m

    def restart(self) -> None:
        """The next call starts a new sweep around where the vehicle is then."""
        self.anchor_across_m = None
        self.anchor_xy = None

    def velocity(
        self, frame: WindFrame, x_m: float, y_m: float, cap_m: float | None = None
    ) -> tuple[float, float]:
        """The sweep's velocity at (x, y) in ``frame``; ``cap_m``: this sweep's cap on the
        half-width instead of ``max_half_width_m``."""
        if self.about_anchor:
            if self.anchor_xy is None:
                self.anchor_xy = (x_m, y_m)
            x_m, y_m = x_m - self.anchor_xy[0], y_m - self.anchor_xy[1]
        _, across = frame.coordinates(x_m, y_m)
        if self.anchor_across_m is None:
            self.anchor_across_m = across
            self.half_width_m = self.first_half_width_m
        if (across - self.anchor_across_m) * self.side > self.half_width_m:
            self.side = -self.side
            cap = self.max_half_width_m if cap_m is None else cap_m
            self.half_width_m = min(self.half_width_m * self.growth, cap)
            self.legs += 1
        return frame.velocity(self.drift_m_s, self.speed_m_s * self.side)
