"""Building a vehicle's autopilot and flight from a scenario, the one way every runner does.

The autopilot process (:mod:`agents.autopilot_node`) and the in-process runners
(``plumeswarm.experiments.fused``, ``plumeswarm.gsl.episode``) build their vehicles here, so both
fly the
same bits (docs/architecture.md, "How a tick flows"). Imports no Zenoh.
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np

from agents.autopilot import Autopilot
from agents.behavior import BehaviorContext, load_behavior
from agents.estimator import Estimator
from agents.flight import Flight
from agents.peer_link import Mailbox
from agents.sensor import ConcentrationSensor
from swarmbus.options import RoleOptions
from swarmbus.scenario import Scenario

NonNegative = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]


class AutopilotOptions(RoleOptions, frozen=True, kw_only=True):
    """The autopilot role's options (``plumeswarm node autopilot --set KEY=VALUE``)."""

    status_period_s: NonNegative = 0.5
    """Sim seconds between unchanged statuses (a stepped world gets one every tick)."""
    position_noise_m: NonNegative = 0.0
    """Standard deviation of the position estimate's noise (0: the physics' truth)."""
    velocity_noise_m_s: NonNegative = 0.0
    """Standard deviation of the velocity estimate's noise (0: the physics' truth)."""
    checkpoint: str = ""
    """File of the process's checkpoints (:mod:`agents.resume`): a restarted process, or a
    physics resumed from its checkpoint, carries on with the same bits. Empty: none."""


def vehicle_index(scenario: Scenario, vehicle_id: str) -> int:
    """Where ``vehicle_id`` is in the scenario (and in every tick); ``ValueError`` if absent."""
    return [v.id for v in scenario.vehicles].index(vehicle_id)


def behavior_rng(scenario: Scenario, vehicle_id: str) -> np.random.Generator:
    """The generator a vehicle's behaviour gets in its context."""
    index = vehicle_index(scenario, vehicle_id)
    seed = scenario.world.seed
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, index, 0xBE4])))


def build_autopilot(
    scenario: Scenario,
    vehicle_id: str,
    options: AutopilotOptions,
    rng: np.random.Generator | None = None,
    mailbox: Mailbox | None = None,
) -> Autopilot:
    """``rng``: the behaviour's generator (default: :func:`behavior_rng`); ``mailbox``: the
    behaviour's end of the radio, where the runner carries peer messages."""
    index = vehicle_index(scenario, vehicle_id)
    estimator = Estimator(
        options.position_noise_m,
        options.velocity_noise_m_s,
        np.random.SeedSequence([scenario.world.seed, index, 0xE57]),
    )
    spec = scenario.vehicle(vehicle_id).behavior
    behavior = None
    if spec is not None:
        ctx = BehaviorContext(
            vehicle_id=vehicle_id,
            vehicle_index=index,
            scenario=scenario,
            control_dt_s=1.0 / scenario.time.control_hz,
            rng=rng if rng is not None else behavior_rng(scenario, vehicle_id),
            mailbox=mailbox,
        )
        behavior = load_behavior(spec, ctx)
    return Autopilot(scenario, vehicle_id, estimator=estimator, behavior=behavior)


def build_flight(
    scenario: Scenario,
    vehicle_id: str,
    options: AutopilotOptions,
    mailbox: Mailbox | None = None,
) -> Flight:
    """A vehicle's autopilot, sensor and behaviour's generator, seeded from the scenario and
    the vehicle's index (``mailbox``: its behaviour's end of the radio)."""
    rng = behavior_rng(scenario, vehicle_id)
    sensor = ConcentrationSensor.for_vehicle(scenario, vehicle_index(scenario, vehicle_id))
    return Flight(build_autopilot(scenario, vehicle_id, options, rng, mailbox), sensor, rng)
