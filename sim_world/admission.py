"""Who may take part in the lockstep: a participant's token counts only once a health of its
process (``NodeHealth.vehicles``; the plume's) carried the physics's scenario hash
(:func:`swarmbus.scenario.scenario_hash`), so hosts started with different scenario files are
refused at the handshake, each refusal logged once with both hashes. A participant whose
process says no hash (an older node, a stand-in) is let in; one whose health is not heard within
:data:`UNCHECKED_ADMIT_S` of its token is let in unchecked (logged).

See docs/physics.md, "Lockstep".
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from sim_world.plume_part import PLUME
from swarmbus.messages import NodeHealth

log = logging.getLogger(__name__)

UNCHECKED_ADMIT_S = 2.0  # a node's health is heard within its period (1 s) of its token


class Admission:
    """Thread-safe: fed from Zenoh's callbacks; ``admit(token name)`` is called outside the
    lock when a pending arrival is let in."""

    def __init__(self, scenario_hash: str, admit: Callable[[str], None]) -> None:
        self._own = scenario_hash
        self._admit = admit
        self._lock = threading.Condition()
        self._checked: set[str] = set()  # participants whose process has our scenario
        self._refused: set[str] = set()  # … has another
        self._refused_nodes: set[str] = set()  # processes refused (each logged once)
        self._pending: dict[str, str] = {}  # participant → its token, waiting for a health
        self._admitted: set[str] = set()
        self._letting_in = 0  # pending arrivals taken out, their ``admit`` not yet done

    def health(self, health: NodeHealth) -> None:
        """A process said its scenario hash: check its participants, let pending ones in."""
        if health.role == "autopilot":
            participants = list(health.vehicles)
        elif health.role == "plume":
            participants = [PLUME]
        else:
            return
        same = not health.scenario or not self._own or health.scenario == self._own
        let_in = []
        with self._lock:
            for p in participants:
                if same:
                    self._checked.add(p)
                    self._refused.discard(p)
                    if p in self._pending:
                        let_in.append(self._pending.pop(p))
                        self._admitted.add(p)
                else:
                    self._refused.add(p)
                    self._checked.discard(p)
                    self._pending.pop(p, None)
                    self._lock.notify_all()
            self._letting_in += len(let_in)
            first = not same and health.name not in self._refused_nodes
            if same:
                self._refused_nodes.discard(health.name)
            else:
                self._refused_nodes.add(health.name)
        if first:
            log.error(
                "refusing %s: scenario hash %s there, %s here (started with a different "
                "scenario file)",
                health.name,
                health.scenario,
                self._own,
            )
        self._let_in(let_in)

    def _let_in(self, names: list[str]) -> None:
        try:
            for name in names:
                self._admit(name)
        finally:
            with self._lock:
                self._letting_in -= len(names)
                self._lock.notify_all()

    def arrival(self, participant: str, name: str) -> bool:
        """``participant``'s token ``name`` came: whether it takes part now (False: refused,
        or waiting for its process's health)."""
        with self._lock:
            refused = participant in self._refused
            if not refused and participant in self._checked:
                self._admitted.add(participant)
                return True
            if not refused:
                self._pending[participant] = name
                timer = threading.Timer(UNCHECKED_ADMIT_S, self._unchecked, (participant,))
                timer.daemon = True
                timer.start()
                return False
        log.warning("%s arrived: refused (another scenario), not a participant", name)
        return False

    def departure(self, participant: str) -> bool:
        """``participant``'s token went: whether it had been let in."""
        with self._lock:
            self._pending.pop(participant, None)
            self._checked.discard(participant)  # its next process says its hash anew
            if participant in self._admitted:
                self._admitted.discard(participant)
                return True
            return False

    def wait_settled(self, timeout_s: float = UNCHECKED_ADMIT_S + 0.5) -> None:
        """Before the first tick: until every token that came is let in or refused (bounded),
        so that tick 0 has the same participants as without the check."""
        with self._lock:
            self._lock.wait_for(lambda: not self._pending and not self._letting_in, timeout_s)

    def _unchecked(self, participant: str) -> None:
        with self._lock:
            name = self._pending.pop(participant, None)
            if name is not None:
                self._admitted.add(participant)
                self._letting_in += 1
        if name is not None:
            log.warning(
                "%s: no health with a scenario hash within %.1f s of its token: let in unchecked",
                name,
                UNCHECKED_ADMIT_S,
            )
            self._let_in([name])
