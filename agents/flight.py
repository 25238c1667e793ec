"""One vehicle's share of a control tick, without any I/O: its autopilot and its sensor.

The autopilot process (:mod:`agents.autopilot_node`) and the in-process fused runner drive the
same :class:`Flight` objects in the same order, so both give the same bits:

1. at tick ``k``, :func:`take_readings` turns the plume's values for the last sensor tick
   ``j < k`` (every vehicle's position at ``j``) into each due vehicle's reading; the reading
   waits in :attr:`Flight.new_readings`;
2. :meth:`Flight.step` runs the autopilot on tick ``k``'s state and hands it those readings
   (a behaviour sees the reading of sensor tick ``j`` at tick ``k``), then forgets them.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import Protocol

import numpy as np

from agents.autopilot import Autopilot
from agents.sensor import ConcentrationSensor
from swarmbus.messages import ConcentrationReading, PeerReading, VehicleState


class Located(Protocol):
    """Who and where: a ``VehicleState`` or anything with the same two fields."""

    @property
    def vehicle_id(self) -> str: ...

    @property
    def position_enu_m(self) -> tuple[float, float, float]: ...


class Flight:
    """One vehicle's autopilot and sensor, and the readings its next step will see
    (``behavior_rng``: the generator its behaviour draws from, kept for checkpoints)."""

    def __init__(
        self,
        autopilot: Autopilot,
        sensor: ConcentrationSensor,
        behavior_rng: np.random.Generator | None = None,
    ) -> None:
        self.vehicle_id = autopilot.vehicle_id
        self.autopilot = autopilot
        self.sensor = sensor
        self.behavior_rng = behavior_rng
        self.new_readings: list[ConcentrationReading] = []

    def step(self, state: VehicleState, peers: Sequence[VehicleState]) -> list[float]:
        """Rotor commands for this tick; the waiting readings go to the behaviour, once."""
        rotor = self.autopilot.step(state, peers, self.new_readings)
        self.new_readings = []
        return rotor


def take_readings(
    flights: Iterable[Flight],
    sensor_tick: int,
    sim_time_s: float,
    located: Sequence[Located],
    values_g_m3: Sequence[float] | None,
) -> list[tuple[Flight, ConcentrationReading]]:
    """The readings of ``sensor_tick`` for the flights due then, each queued on its flight.

    ``located`` lists every vehicle of the tick (the plume was asked at these positions) and
    ``values_g_m3`` the plume's answer, one per position (``None``: no answer → unavailable).
    """
    index: dict[str, int] = {}
    for k, s in enumerate(located):
        index.setdefault(s.vehicle_id, k)
    # Every vehicle's PeerReading, built once per tick and shared by the flights' readings
    # (frozen): K x N constructions per tick would be N.
    everyone: list[PeerReading] | None = None
    out: list[tuple[Flight, ConcentrationReading]] = []
    for flight in flights:
        if not flight.sensor.due(sensor_tick):
            continue
        own = index.get(flight.vehicle_id)
        if own is None:
            continue
        position = located[own].position_enu_m
        true = values_g_m3[own] if values_g_m3 is not None else None
        peers: list[PeerReading] = []
        if values_g_m3 is not None:
            if everyone is None:
                everyone = [
                    PeerReading(
                        vehicle_id=s.vehicle_id,
                        position_enu_m=s.position_enu_m,
                        true_g_m3=values_g_m3[k],
                    )
                    for k, s in enumerate(located)
                ]
            peers = everyone[:own] + everyone[own + 1 :]
        reading = flight.sensor.reading(flight.vehicle_id, sim_time_s, position, true, peers)
        flight.autopilot.sensor_health = (
            "" if reading.available else "sensor: the plume service did not answer"
        )
        flight.new_readings.append(reading)
        out.append((flight, reading))
    return out
