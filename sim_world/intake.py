"""Actuator intake: which entries of an ``ActuatorBatch`` count as a vehicle's command.

See docs/physics.md, "Lockstep" (rules 3 and 5).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Sequence

from swarmbus.codec import MessageError, decode, refusals
from swarmbus.keys import KeyNameError, vehicle_of_autopilot
from swarmbus.messages import ActuatorBatch, ActuatorCommand
from swarmbus.views import BatchView

log = logging.getLogger(__name__)


class ActuatorIntake:
    """Decodes a batch and keeps the entries the barrier may count; logs and counts the rest."""

    def __init__(self, vehicle_ids: Iterable[str], node_of_key: Callable[[str], str]) -> None:
        self._known = frozenset(vehicle_ids)
        self._node_of_key = node_of_key  # the node name in an autopilot/<node>/actuators key
        self.foreign_dropped = 0  # commands for another vehicle on a one-vehicle node's key
        self._foreign_logged: set[str] = set()  # the keys that sent them (logged once each)

    def entries(self, key: str, data: bytes) -> tuple[int, list[tuple[str, Sequence[float]]]]:
        """The batch's tick and its ``(vehicle_id, rotor_commands)`` entries that may count."""
        try:
            batch = decode(data, ActuatorBatch)
            tick, commands = batch.tick, batch.commands
        except MessageError as exc:
            salvaged = _salvage(key, data, exc)
            if salvaged is None:
                return 0, []
            tick, commands = salvaged
        only = self._sender_vehicle(key)
        kept: list[tuple[str, Sequence[float]]] = []
        for cmd in commands:
            vid = cmd.vehicle_id
            if only is not None and vid != only:
                self._drop_foreign(key, vid)
            elif cmd.tick != tick or vid not in self._known:
                log.warning(
                    "ignoring actuators for %s of tick %d in the batch of tick %d on %s",
                    vid,
                    cmd.tick,
                    tick,
                    key,
                )
            else:
                kept.append((vid, cmd.rotor_commands))
        return tick, kept

    def _sender_vehicle(self, key: str) -> str | None:
        """The one vehicle a batch on ``key`` may command: ``<id>`` on a one-vehicle node's
        key (``autopilot/autopilot-<id>/actuators``, the only key a per-vehicle identity may
        put on), None on any other node's key (a process serving several vehicles)."""
        try:
            vid = vehicle_of_autopilot(self._node_of_key(key))
        except KeyNameError:
            return None
        return vid if vid in self._known else None

    def _drop_foreign(self, key: str, vehicle_id: str) -> None:
        """Count a command for ``vehicle_id`` on another vehicle's key (logged once a key)."""
        self.foreign_dropped += 1
        if key not in self._foreign_logged:
            self._foreign_logged.add(key)
            log.warning(
                "ignoring actuators for %s on %s: a one-vehicle node commands only its own "
                "vehicle (further ones from this key are counted in the health detail)",
                vehicle_id,
                key,
            )


def _salvage(key: str, data: bytes, exc: MessageError) -> tuple[int, list[ActuatorCommand]] | None:
    """The good entries of a batch that failed to decode (each bad one is logged)."""
    try:
        view = decode(data, BatchView)
    except MessageError:
        refusals(log).refuse(key, f"actuator batch on {key}", exc)
        return None
    good = []
    for k, raw in enumerate(view.commands):
        try:
            good.append(decode(raw, ActuatorCommand))
        except MessageError as bad:
            refusals(log).refuse(key, f"entry {k} of the actuator batch on {key}", bad, "entry")
    return view.tick, good
