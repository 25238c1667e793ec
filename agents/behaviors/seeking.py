"""The base of the source-seeking behaviours: what every one of them does before deciding.

:class:`SeekingBehavior` runs the common preamble of each control tick and then the
algorithm's own :meth:`~SeekingBehavior.seek`:

1. the altitude: the first step fixes the altitude the search flies at (the vehicle's own);
2. once the source is declared (``self.declaration``), hold over it and decide nothing more;
3. read the wind (``self.read_wind``, the vehicle's anemometer by default,
   :func:`agents.behaviors.wind.anemometer_wind`) and its frame;
4. ``seek(step)``: the algorithm's setpoint from what it has at this step (:class:`SeekStep`:
   ``own``, ``peers``, ``readings``, ``wind``, and ``inbox``: the peers' messages that reached
   it for this step, :mod:`agents.peer_link`); if it declared the source during that call, the
   setpoint holds over the declaration instead.

Its state (``altitude_m``, ``declaration``) is saved with the subclass's own
``state_attributes`` (:class:`agents.behavior_state.SavesState`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import ClassVar

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behavior_state import SavesState
from agents.behaviors.steering import hold_at, start_or_hold
from agents.behaviors.wind import WindFrame, WindReader, anemometer_wind
from agents.peer_link import Mailbox, Received
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState


@dataclass(frozen=True)
class Wind:
    """The wind read at this step: the (east, north) air velocity in m/s and its frame."""

    vector_m_s: tuple[float, float]
    frame: WindFrame


@dataclass(frozen=True)
class SeekStep:
    """What a source-seeking behaviour has at one control step: its vehicle's state, its
    peers' states, the readings that reached it since the last step, the wind read now, and
    the peers' messages that reached it for this step."""

    own: VehicleState
    peers: Sequence[VehicleState]
    readings: Sequence[ConcentrationReading]
    wind: Wind
    inbox: Sequence[Received] = ()


class SeekingBehavior(SavesState, ABC):
    """A source-seeking behaviour: subclasses implement :meth:`seek` and list their own state
    in ``own_state``; the base adds ``altitude_m`` and ``declaration`` to it."""

    own_state: ClassVar[tuple[str, ...]] = ()

    def __init_subclass__(cls) -> None:
        super().__init_subclass__()
        cls.state_attributes = (*cls.own_state, "altitude_m", "declaration")

    def __init__(self, ctx: BehaviorContext) -> None:
        self.read_wind: WindReader = anemometer_wind(ctx)
        self.mailbox: Mailbox | None = ctx.mailbox
        self.altitude_m: float | None = None
        self.declaration: SourceEstimate | None = None

    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None:
        self.altitude_m, held = start_or_hold(own, self.altitude_m, self.declaration)
        if held is not None:
            return held
        vector = self.read_wind(own)
        inbox = self.mailbox.inbox if self.mailbox is not None else ()
        wind = Wind(vector, WindFrame.of(vector))
        setpoint = self.seek(SeekStep(own, peers, readings, wind, inbox))
        if self.declaration is not None:
            return hold_at(self.declaration.x_m, self.declaration.y_m, self.altitude_m)
        return setpoint

    @property
    def altitude(self) -> float:
        """The altitude the search flies at (set by the first step)."""
        assert self.altitude_m is not None
        return self.altitude_m

    @abstractmethod
    def seek(self, step: SeekStep) -> Setpoint | None:
        """The algorithm's setpoint for this step; set ``self.declaration`` to declare."""
