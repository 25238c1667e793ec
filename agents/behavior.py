"""Behaviour plug-ins: ``module:Class`` in the scenario (``[[vehicles]] behavior``).

The class is built once with a :class:`BehaviorContext`; while its vehicle is in offboard mode,
``step(own, peers, readings)`` is called every control tick and returns the
:class:`~swarmbus.messages.Setpoint` to fly (``None``: no new setpoint; the stream timeout
then applies). ``readings`` are the vehicle's own concentration readings that arrived since the
previous step (usually one per sensor period; a reading describes the previous sensor tick).

A behaviour that decides where the source is sets its ``declaration`` attribute to a
:class:`SourceEstimate` (once; it then holds position). Runners read it; the bench
``plumeswarm bench gsl`` scores the declared position instead of where the vehicle ends.
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from agents.peer_link import Mailbox
from swarmbus.errors import PlumeswarmError
from swarmbus.messages import ConcentrationReading, Setpoint, VehicleState
from swarmbus.scenario import Scenario


@dataclass(frozen=True)
class SourceEstimate:
    """Where a behaviour believes the source is: ENU metres, the release rate if it estimates
    one, the 1-σ horizontal spread of its belief if it has one, and when it decided."""

    x_m: float
    y_m: float
    sim_time_s: float
    release_rate_g_s: float | None = None
    spread_m: float | None = None


@dataclass(frozen=True)
class BehaviorContext:
    """What a behaviour is built with. ``mailbox``: its end of the radio to its peers
    (:class:`agents.peer_link.Mailbox`: publish a small typed message, read theirs), where the
    runner carries peer messages; ``None`` where it does not."""

    vehicle_id: str
    vehicle_index: int
    scenario: Scenario
    control_dt_s: float
    rng: np.random.Generator
    mailbox: Mailbox | None = None


class Behavior(Protocol):
    def step(
        self,
        own: VehicleState,
        peers: Sequence[VehicleState],
        readings: Sequence[ConcentrationReading],
    ) -> Setpoint | None: ...


class BehaviorError(PlumeswarmError, RuntimeError):
    pass


def behavior_class(spec: str) -> Any:
    """The class ``module:Class`` names; :class:`BehaviorError` if it cannot be imported."""
    module_name, sep, class_name = spec.partition(":")
    if not sep or not module_name or not class_name:
        raise BehaviorError(f"behavior {spec!r}: expected 'module:Class'")
    try:
        module = importlib.import_module(module_name)
        return getattr(module, class_name)
    except (ImportError, AttributeError) as exc:
        raise BehaviorError(f"behavior {spec!r}: {exc}") from None


def talks(spec: str) -> bool:
    """Whether the behaviour ``spec`` names talks to its peers over the radio (its class's
    ``talks``: it needs a runner that carries behaviour messages)."""
    return bool(getattr(behavior_class(spec), "talks", False))


def ignores_peers(spec: str) -> bool:
    """Whether the behaviour ``spec`` names says it never reads its peers (its class's
    ``ignores_peers``; a behaviour that talks reads them whatever it says): no radio changes
    what it does."""
    cls = behavior_class(spec)
    return bool(getattr(cls, "ignores_peers", False)) and not getattr(cls, "talks", False)


def load_behavior(spec: str, ctx: BehaviorContext) -> Behavior:
    """Import ``module:Class`` and build it with ``ctx``; :class:`BehaviorError` if it fails."""
    cls = behavior_class(spec)
    class_name = spec.partition(":")[2]
    behavior = cls(ctx)
    if not callable(getattr(behavior, "step", None)):
        raise BehaviorError(f"behavior {spec!r}: {class_name} has no step() method")
    return behavior  # type: ignore[no-any-return]
