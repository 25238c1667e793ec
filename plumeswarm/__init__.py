"""plumeswarm — a swarm of UAVs flying through a gas plume, on a Zenoh bus.

This package is what users import and run: the CLI (``plumeswarm``), the Gymnasium and
PettingZoo environments (:mod:`plumeswarm.envs`), the source-seeking benchmark
(:mod:`plumeswarm.gsl`), the experiments (:mod:`plumeswarm.experiments`: demo, fused runner,
drivers, chaos) and the performance benches (:mod:`plumeswarm.bench`). The simulator's processes
live in their own packages below it (docs/architecture.md, "Layers").

The names below load on first use, so ``import plumeswarm`` stays light::

    import plumeswarm
    with plumeswarm.Swarm.connect() as sw: ...
    plume = plumeswarm.GaussianPlume.preset("novak2018")
"""

from __future__ import annotations

import importlib
from importlib.metadata import PackageNotFoundError, version
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from agents.behavior import Behavior, BehaviorContext
    from agents.behaviors.seeking import SeekingBehavior
    from agents.swarm import (
        ClockError,
        CommandRejected,
        CommandTimeout,
        PlumeError,
        RadioReadError,
        RadioSent,
        RadioUnavailable,
        Swarm,
        SwarmError,
        VehicleCommander,
        WaitTimeout,
    )
    from plume_service.filament import FilamentPlume
    from plume_service.gaussian import GaussianPlume
    from plume_service.puff import PuffPlume
    from plumeswarm.experiments.driver import BusDriver, Driver, InProcessDriver
    from plumeswarm.experiments.fused import FusedRunner
    from recorder.reader import Recording
    from swarmbus.errors import PlumeswarmError
    from swarmbus.scenario import Scenario, ScenarioError, load_scenario

# public name -> the module that defines it
_PUBLIC: dict[str, str] = {
    "Behavior": "agents.behavior",
    "BehaviorContext": "agents.behavior",
    "BusDriver": "plumeswarm.experiments.driver",
    "ClockError": "agents.swarm",
    "CommandRejected": "agents.swarm",
    "CommandTimeout": "agents.swarm",
    "Driver": "plumeswarm.experiments.driver",
    "FilamentPlume": "plume_service.filament",
    "FusedRunner": "plumeswarm.experiments.fused",
    "GaussianPlume": "plume_service.gaussian",
    "InProcessDriver": "plumeswarm.experiments.driver",
    "PlumeError": "agents.swarm",
    "PlumeswarmError": "swarmbus.errors",
    "PuffPlume": "plume_service.puff",
    "RadioReadError": "agents.swarm",
    "RadioSent": "agents.swarm",
    "RadioUnavailable": "agents.swarm",
    "Recording": "recorder.reader",
    "Scenario": "swarmbus.scenario",
    "ScenarioError": "swarmbus.scenario",
    "SeekingBehavior": "agents.behaviors.seeking",
    "Swarm": "agents.swarm",
    "SwarmError": "agents.swarm",
    "VehicleCommander": "agents.swarm",
    "WaitTimeout": "agents.swarm",
    "load_scenario": "swarmbus.scenario",
}

try:
    __version__ = version("plumeswarm")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

__all__ = [
    "Behavior",
    "BehaviorContext",
    "BusDriver",
    "ClockError",
    "CommandRejected",
    "CommandTimeout",
    "Driver",
    "FilamentPlume",
    "FusedRunner",
    "GaussianPlume",
    "InProcessDriver",
    "PlumeError",
    "PlumeswarmError",
    "PuffPlume",
    "RadioReadError",
    "RadioSent",
    "RadioUnavailable",
    "Recording",
    "Scenario",
    "ScenarioError",
    "SeekingBehavior",
    "Swarm",
    "SwarmError",
    "VehicleCommander",
    "WaitTimeout",
    "__version__",
    "load_scenario",
]


def __getattr__(name: str) -> Any:
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'plumeswarm' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
