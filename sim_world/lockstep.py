"""The lockstep barrier as pure logic: who the current tick waits for, and when to give up.

Driven by events (a participant's liveliness token came or went, a command arrived, a tick
began) and an injected clock function, so it is tested with a fake clock; the physics node
feeds it from Zenoh callbacks under its own lock.

A vehicle's participant is *present* while its ``autopilot-<id>`` token is alive, and *active*
while the barrier waits for it. :meth:`Lockstep.start` makes every present participant active
(the start-up handshake). A participant that misses the deadline of a tick is dropped (no longer
active: its motors go to zero); a dropped or newly arrived participant becomes active again
as soon as it answers a tick published since (it has caught up), and is waited for from then on.
With a ``rejoin_window`` (realtime mode) the tick it answers must also be one of the last few:
an answer that sat in a healed link's backlog says nothing of how soon it answers the next.

A *periodic* participant (the plume service, which answers every sensor tick) is waited for only
on the ticks its period divides, and is no vehicle: the start does not wait for its token
(:meth:`Lockstep.missing_tokens` names vehicles only) and its answers are no motor commands
(:meth:`Lockstep.commands` holds the vehicles' alone). Otherwise it is a participant like any:
present, active, dropped, rejoining and held by the same rules.

Restarts (lockstep mode): a participant whose token goes while the launcher may be restarting
its process is *held* instead (:meth:`Lockstep.held_leave`): it stays active, the tick waits
for it until its usual deadline (time for the launcher's word), and a restart notice
(:meth:`Lockstep.restarting`) extends the wait to the grace. Its new process answers the held
tick like any tick; after the grace it is dropped like a silent participant.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

from swarmbus.keys import vehicle_of_autopilot


def participant_of(node_name: str, vehicle_ids: Iterable[str]) -> str | None:
    """The vehicle id whose autopilot token ``node_name`` is, or ``None``."""
    vid = vehicle_of_autopilot(node_name)
    return vid if vid is not None and vid in vehicle_ids else None


class Lockstep:
    """Barrier state for one world; not thread-safe (the caller holds a lock)."""

    def __init__(
        self,
        vehicle_ids: Sequence[str],
        timeout_s: float,
        clock: Callable[[], float],
        periodic: Mapping[str, int] | None = None,
        rejoin_window: int | None = None,
    ) -> None:
        self.vehicle_ids = tuple(vehicle_ids)
        self.rejoin_window = rejoin_window  # ticks behind the current one an answer rejoins
        self._periods = dict(periodic or {})  # participant → its period in ticks (>= 1)
        if any(p < 1 for p in self._periods.values()) or self._periods.keys() & set(vehicle_ids):
            raise ValueError(f"bad periodic participants {self._periods}")
        self._order = (*self.vehicle_ids, *self._periods)
        self.participants = frozenset(self._order)  # vehicles and periodic participants
        self.timeout_s = timeout_s
        self._clock = clock
        self._present: set[str] = set()
        self._active: set[str] = set()
        self._waiting: set[str] = set()  # active and not yet answered the current tick
        # A non-active participant becomes active by answering a tick >= this.
        self._rejoin_from: dict[str, int] = {}
        self.tick = 0
        self._deadline = clock() + timeout_s
        self._commands: dict[str, Sequence[float]] = {}
        # Held participants (token gone, restart possible): wall time until which the tick
        # waits for each; None until the launcher's notice (the tick's own deadline applies).
        self._held: dict[str, float | None] = {}
        # Participants that became active again by answering (participant, tick), for the log.
        self.rejoined: list[tuple[str, int]] = []

    # ------------------------------------------------------------------ presence
    def joined(self, vehicle_id: str) -> bool:
        """A participant's token appeared; returns whether it is one of ours."""
        if vehicle_id not in self.participants:
            return False
        if vehicle_id not in self._present:
            self._present.add(vehicle_id)
            self._rejoin_from[vehicle_id] = 0
        return True

    def left(self, vehicle_id: str) -> bool:
        """A participant's token disappeared: stop waiting for it at once."""
        if vehicle_id not in self.participants:
            return False
        self._present.discard(vehicle_id)
        self._active.discard(vehicle_id)
        self._waiting.discard(vehicle_id)
        self._commands.pop(vehicle_id, None)
        self._held.pop(vehicle_id, None)
        return True

    @property
    def present(self) -> frozenset[str]:
        return frozenset(self._present)

    @property
    def active(self) -> frozenset[str]:
        return frozenset(self._active)

    def missing_tokens(self) -> list[str]:
        """Configured vehicles whose autopilot is not present, in scenario order."""
        return [v for v in self.vehicle_ids if v not in self._present]

    # ------------------------------------------------------------------ ticks
    def start(self) -> None:
        """Every present participant takes part from now on (before tick 0)."""
        self._active = set(self._present)
        waiting = {p for p in self._active if self.waits_for(p, self.tick)}
        self._waiting = waiting - self._commands.keys()

    def begin(self, tick: int, timeout_s: float | None = None) -> None:
        """Tick ``tick`` was published: wait for its commands until the deadline."""
        self.tick = tick
        self._commands = {}
        self._waiting = {p for p in self._active if self.waits_for(p, tick)}
        self._deadline = self._clock() + (self.timeout_s if timeout_s is None else timeout_s)

    def receive(self, vehicle_id: str, tick: int, rotor_commands: Sequence[float]) -> bool:
        """A command arrived; returns whether it counts for the current tick."""
        if vehicle_id not in self._present or not self.waits_for(vehicle_id, tick):
            return False  # no token, no participant; or not a tick it answers
        if vehicle_id not in self._active:
            if tick < self._rejoin_from.get(vehicle_id, 0):
                return False  # sent before it was dropped
            if self.rejoin_window is not None and tick < self.tick - self.rejoin_window:
                return False  # an old answer, late: it has not caught up
            self._active.add(vehicle_id)
            self.rejoined.append((vehicle_id, tick))
            if self.waits_for(vehicle_id, self.tick):
                self._waiting.add(vehicle_id)
        if tick != self.tick:
            return False
        self._commands[vehicle_id] = rotor_commands
        self._waiting.discard(vehicle_id)
        if self._held:
            self._held.pop(vehicle_id, None)  # its new process answered: the hold is over
        return True

    def waits_for(self, participant: str, tick: int) -> bool:
        """Whether ``participant`` answers ``tick`` (a periodic one: only the ticks its period
        divides), if it is active."""
        period = self._periods.get(participant)
        return period is None or tick % period == 0

    def waits(self, participant: str) -> bool:
        """Whether the current tick waits for ``participant``'s answer (still)."""
        return participant in self._waiting

    def complete(self) -> bool:
        """Every active participant has answered the current tick."""
        return not self._waiting

    def missing(self) -> list[str]:
        """Active participants that have not answered the current tick, in scenario order
        (vehicles, then the periodic participants)."""
        return [v for v in self._order if v in self._waiting]

    def remaining_s(self) -> float:
        if self._held:
            return self._held_deadline() - self._clock()
        return self._deadline - self._clock()

    def late(self) -> list[str]:
        """Missing participants whose token is up (late, not gone), in :meth:`missing` order."""
        return [p for p in self.missing() if p in self._present]

    def expire(self) -> list[str]:
        """After the deadline, drop whoever has not answered; returns the dropped ids."""
        if self.remaining_s() > 0.0:
            return []
        dropped = self.missing()
        self.drop(dropped)
        return dropped

    def drop(self, dropped: Sequence[str]) -> None:
        """Stop waiting for ``dropped`` (missing participants) until they answer again."""
        for vid in dropped:
            self._active.discard(vid)
            self._waiting.discard(vid)
            self._rejoin_from[vid] = self.tick
            self._held.pop(vid, None)

    def extend(self, until_s: float) -> None:
        """The current tick waits for its missing participants until ``until_s`` (clock time)."""
        self._deadline = max(self._deadline, until_s)

    def commands(self) -> dict[str, Sequence[float]]:
        """The current tick's commands of active vehicles (others get zero motors)."""
        return {
            v: c for v, c in self._commands.items() if v in self._active and v not in self._periods
        }

    # ------------------------------------------------------------------ restarts
    def held_leave(self, vehicle_id: str) -> bool:
        """A participant's token disappeared and its process may be restarted: hold it (see
        the module doc) instead of :meth:`left`; returns whether it is one of ours."""
        if vehicle_id not in self.participants:
            return False
        self._present.discard(vehicle_id)
        if vehicle_id in self._active:
            self._held.setdefault(vehicle_id, None)
        return True

    def restarting(self, vehicle_id: str, grace_s: float) -> bool:
        """The launcher is restarting this participant's process: the tick waits for it up to
        ``grace_s`` from now. Returns whether it is held (an active participant of ours)."""
        if vehicle_id not in self._active:
            return False
        self._held[vehicle_id] = self._clock() + grace_s
        return True

    def gone(self, vehicle_id: str) -> bool:
        """The launcher will not restart it: stop waiting for it now, like :meth:`left`."""
        return self.left(vehicle_id) if vehicle_id not in self._present else False

    @property
    def held(self) -> frozenset[str]:
        """Participants the current tick holds for (token gone, restart possible)."""
        return frozenset(self._held)

    def _held_deadline(self) -> float:
        # The tick ends no earlier than its own deadline, nor before the longest hold of a
        # participant it still waits for (the others simply wait with it).
        holds = [u for v, u in self._held.items() if u is not None and v in self._waiting]
        return max([self._deadline, *holds])
