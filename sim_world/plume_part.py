"""The plume service's part in the lockstep: who it is, and what each tick carries of it.

See docs/physics.md, "The plume's part".
"""

from __future__ import annotations

import logging

from swarmbus.codec import decode_or_none
from swarmbus.messages import FieldSample, PlumeSample

log = logging.getLogger(__name__)

PLUME = "plume"  # the plume service's participant in the lockstep (any node named plume[-*])


def is_plume(node_name: str) -> bool:
    """Whether ``node_name`` is a plume service's token (``plume`` or ``plume-…``)."""
    return node_name == PLUME or node_name.startswith(PLUME + "-")


def decode_answer(data: bytes, key: object) -> FieldSample | None:
    """A ``FieldSample`` from ``field/sample``, or None (logged) if it does not decode."""
    return decode_or_none(data, FieldSample, "plume sample", log, str(key))


class PlumeParticipation:
    """The live plume services (one participant), the answer to the current tick and the
    values the next tick carries; not thread-safe (the physics node holds its lock)."""

    def __init__(self) -> None:
        self._nodes: set[str] = set()
        self._answer: FieldSample | None = None  # the answer to the current tick
        self._queried = False  # the current tick waits for an answer
        self._states = 0  # how many states the current tick has
        self.carried: PlumeSample | None = None  # what the next published tick carries

    def presence(self, node_name: str, alive: bool) -> bool:
        """A plume service's token came or went; whether the participant did (the first
        service came, the last one went)."""
        was = bool(self._nodes)
        if alive:
            self._nodes.add(node_name)
        else:
            self._nodes.discard(node_name)
        return was != bool(self._nodes)

    def answered(self, answer: FieldSample) -> None:
        """The barrier counted ``answer`` for the current tick."""
        self._answer = answer

    def published(self, queried: bool, states: int) -> PlumeSample | None:
        """A tick of ``states`` states goes out (waiting for an answer if ``queried``); returns
        the values it carries (those of the last sensor tick), which are then spent."""
        self._queried = queried
        self._states = states
        carried, self.carried = self.carried, None
        return carried

    def take(self, tick: int) -> None:
        """The current tick ``tick`` is done: what the next one carries becomes its answer if
        it waited for one (values None if none came or it does not fit the tick's states).
        Taken every tick: an answer that came for a tick that did not wait for it is dropped."""
        answer, self._answer = self._answer, None
        if not self._queried:
            self.carried = None
            return
        values = answer.values_g_m3 if answer is not None else None
        if values is not None and len(values) != self._states:
            log.warning(
                "tick %d: plume sampled %d points of %d states", tick, len(values), self._states
            )
            values = None
        self.carried = PlumeSample(tick=tick, values_g_m3=values)
