"""The fused runner: the whole lockstep in one process, no bus.

The same :class:`~sim_world.world.World`, the same autopilots and sensors
(:class:`agents.flight.Flight`, built as the autopilot process builds them) and the same plume
service object answer the same questions in the same order as the distributed stack, so for
the same scenario, seed and commands the state stream is the same, bit for bit. One tick ``k``:

1. the physics has the states of tick ``k`` (the physics process publishes them in ``sim/tick``);
   on a sensor tick the plume samples every vehicle's position at ``k`` (the plume service
   answers that tick with its ``FieldSample``);
2. each autopilot first takes the readings of the last sensor tick before ``k`` (the plume's
   answer arrives with tick ``k`` in the distributed stack), then steps on tick ``k``'s state;
   What a vehicle learns of its peers (their states, their samples, their behaviours'
   messages) passes through the scenario's ``[radio]`` (:class:`agents.peer_link.PeerLink`;
   the default, perfect link hands every peer's state and sample over unchanged);
3. the physics applies the rotor commands of tick ``k``, steps ``substeps`` physics steps and
   has tick ``k + 1``.

:meth:`FusedRunner.step` stops between 2 and 3, where the distributed stack stands when the
client that drives the clock holds it: a command given then (:meth:`FusedRunner.command`)
takes effect on the next tick, always.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

from agents.build import AutopilotOptions, build_flight
from agents.flight import Flight, take_readings
from agents.peer_link import PeerLink
from plume_service.from_scenario import field_from_scenario
from plume_service.service import PlumeService
from sim_world.world import World
from swarmbus.closeable import Closeable
from swarmbus.messages import CommandReply, ConcentrationReading, VehicleState
from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

StatesObserver = Callable[[Sequence[VehicleState]], None]


class FusedRunner(Closeable):
    """A scenario's world, autopilots, sensors and plume in one process; a context manager.

    ``on_states`` sees every tick's states (tick 0 at construction). ``plume=False`` runs
    as a stack without a plume node does: every reading unavailable.
    """

    def __init__(
        self,
        scenario: Scenario,
        options: AutopilotOptions | None = None,
        *,
        plume: bool = True,
        on_states: StatesObserver | None = None,
    ) -> None:
        self.scenario = scenario
        self.world = World(scenario)
        try:
            opts = options or AutopilotOptions()
            self.link = PeerLink(scenario)
            self.flights: dict[str, Flight] = {
                vid: build_flight(scenario, vid, opts, self.link.mailboxes[vid])
                for vid in self.world.vehicle_ids
            }
        except BaseException:
            self.world.close()
            raise
        self._flights = list(self.flights.values())
        self.plume = PlumeService(field_from_scenario(scenario)) if plume else None
        self.substeps = scenario.substeps
        self.control_dt_s = 1.0 / scenario.time.control_hz
        self._sensor_period = scenario.sensor.resolved().period_ticks
        self._on_states = on_states
        self.tick = 0
        self.states: list[VehicleState] = []
        # The last sensor tick's question and answer: (tick, time, states, values or None).
        self._pending: tuple[int, float, list[VehicleState], list[float] | None] | None = None
        self._commands: dict[str, Sequence[float]] = {}
        self.latest_readings: dict[str, ConcentrationReading] = {}
        self._publish()
        self._control()

    # ------------------------------------------------------------------ lifecycle
    def close(self) -> None:
        self.world.close()

    # ------------------------------------------------------------------ the client's side
    @property
    def sim_time_s(self) -> float:
        return self.world.sim_time_s

    def command(self, vehicle_id: str, command: object) -> CommandReply:
        """Hand one command to a vehicle's autopilot (as ``vehicle/<id>/cmd`` does); it
        takes effect on the next tick. ``KeyError`` for an unknown vehicle."""
        return self.flights[vehicle_id].autopilot.handle(command)

    def step(self, ticks: int = 1) -> list[VehicleState]:
        """Advance ``ticks`` control ticks; the states of the last one."""
        for _ in range(ticks):
            for bad in self.world.apply_tick(self._commands):
                log.warning("tick %d: %s; motors off", self.tick, bad)
            self.world.step(self.substeps)
            self.tick += 1
            self._publish()
            self._control()
        return self.states

    # ------------------------------------------------------------------ one tick
    def _publish(self) -> None:
        """The physics' half of a tick: the states."""
        world = self.world
        sim_time_s = world.sim_time_s
        states = self.states = world.states(self.tick, sim_time_s)
        if self._on_states is not None:
            self._on_states(states)

    def _control(self) -> None:
        """The autopilots' half: last sensor tick's readings, then every vehicle's step."""
        states = self.states
        link, tick = self.link, self.tick
        link.before_step(tick)
        # A perfect link hands every peer's state over unchanged and draws nothing: each
        # vehicle's peers are then built only for the behaviours that read them.
        everyone = None if link.perfect else link.peers(tick, states)
        pending, self._pending = self._pending, None
        if pending is not None:
            sensor_tick, sensor_time_s, located, values = pending
            taken = take_readings(self._flights, sensor_tick, sensor_time_s, located, values)
            heard = link.readings(tick, states, [r for _, r in taken])
            for (flight, _), reading in zip(taken, heard, strict=True):
                flight.new_readings[-1] = reading
                self.latest_readings[flight.vehicle_id] = reading
        commands: dict[str, Sequence[float]] = {}
        for own, (flight, state) in enumerate(zip(self._flights, states, strict=True)):
            if flight.autopilot.behavior is None:
                peers = []
            elif everyone is None:
                peers = states[:own] + states[own + 1 :]
            else:
                peers = everyone[own]
            commands[flight.vehicle_id] = flight.step(state, peers)
        link.after_step(tick, states)
        self._commands = commands
        if self.tick % self._sensor_period == 0 and states:
            self._pending = (self.tick, self.world.sim_time_s, states, self._sample_plume(states))

    def _sample_plume(self, states: list[VehicleState]) -> list[float] | None:
        if self.plume is None:
            return None
        points = [s.position_enu_m for s in states]
        return self.plume.sample(self.tick, self.world.sim_time_s, points).values_g_m3
