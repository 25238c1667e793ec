"""Missions: a list of items resolved to the ENU frame, the current item, reached events.

What the MAVLink mission protocol needs later is kept here: the items as uploaded (for
download), the current index, how many items were reached and whether the mission finished.
Guidance for the current item (how to fly it) is the flight modes' job (:mod:`agents.modes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from swarmbus.errors import FieldError
from swarmbus.messages import MissionCommand, MissionFrame, MissionItem
from swarmbus.scenario import Origin


class MissionError(FieldError):
    """An item that cannot be flown: which item, which field, why."""

    def __init__(self, index: int, field: str, reason: str) -> None:
        self.index = index
        super().__init__(f"item {index}", field, reason)


@dataclass(frozen=True, slots=True)
class ResolvedItem:
    """A mission item in the world ENU frame (metres; yaw ENU radians or ``None``)."""

    command: MissionCommand
    x: float
    y: float
    z: float
    acceptance_radius_m: float
    hold_s: float
    speed_m_s: float
    yaw_rad: float | None


def resolve_item(index: int, item: MissionItem, origin: Origin) -> ResolvedItem:
    if item.frame == MissionFrame.GLOBAL:
        if not -90.0 <= item.x <= 90.0:
            raise MissionError(index, "x", f"latitude {item.x} is outside [-90, 90]")
        if not -180.0 <= item.y <= 180.0:
            raise MissionError(index, "y", f"longitude {item.y} is outside [-180, 180]")
        # pymap3d pulls in dateutil (≈ 70 ms, 3 MB per process): load it for global items only.
        import pymap3d

        e, n, u = pymap3d.geodetic2enu(
            item.x, item.y, item.z, origin.lat_deg, origin.lon_deg, origin.alt_m
        )
        x, y, z = float(e), float(n), float(u)
    else:
        x, y, z = item.x, item.y, item.z
    return ResolvedItem(
        command=item.command,
        x=x,
        y=y,
        z=z,
        acceptance_radius_m=item.acceptance_radius_m,
        hold_s=item.hold_s,
        speed_m_s=item.speed_m_s,
        yaw_rad=math.radians(item.yaw_deg) if item.yaw_deg is not None else None,
    )


@dataclass(frozen=True, slots=True)
class ItemReached:
    index: int
    sim_time_s: float


@dataclass
class Mission:
    """Uploaded items and progress through them."""

    items: list[MissionItem] = field(default_factory=list)
    resolved: list[ResolvedItem] = field(default_factory=list)
    index: int = -1
    items_reached: int = 0
    finished: bool = False
    events: list[ItemReached] = field(default_factory=list)
    _hold_started_s: float | None = None

    @property
    def count(self) -> int:
        return len(self.items)

    def upload(self, items: list[MissionItem], origin: Origin) -> None:
        """Replace the mission (raises :class:`MissionError`, leaving the old one intact)."""
        resolved = [resolve_item(i, item, origin) for i, item in enumerate(items)]
        self.items = list(items)
        self.resolved = resolved
        self.index = 0 if items else -1
        self.items_reached = 0
        self.finished = False
        self._hold_started_s = None

    def clear(self) -> None:
        self.upload([], Origin())

    def start(self, index: int = 0) -> None:
        if not 0 <= index < self.count:
            raise MissionError(index, "start_index", f"mission has {self.count} item(s)")
        self.index = index
        self.items_reached = 0
        self.finished = False
        self._hold_started_s = None

    @property
    def current(self) -> ResolvedItem | None:
        if self.finished or not 0 <= self.index < self.count:
            return None
        return self.resolved[self.index]

    def arrived(self, sim_time_s: float) -> bool:
        """The vehicle is inside the current item's acceptance radius: true once the item's
        hold time has passed there (then the item is reached and the mission advances)."""
        item = self.current
        if item is None:
            return False
        if self._hold_started_s is None:
            self._hold_started_s = sim_time_s
        if sim_time_s - self._hold_started_s + 1e-9 < item.hold_s:
            return False
        self.reached(sim_time_s)
        return True

    def reached(self, sim_time_s: float) -> None:
        """Mark the current item reached and move to the next one (or finish)."""
        self.events.append(ItemReached(self.index, sim_time_s))
        self.items_reached += 1
        self._hold_started_s = None
        if self.index + 1 >= self.count:
            self.finished = True
        else:
            self.index += 1

    def drain_events(self) -> list[ItemReached]:
        events, self.events = self.events, []
        return events
