"""``from agents import Swarm``: a client for swarm-algorithm researchers: cached states,
statuses and readings, the radio's messages between vehicles, typed commands and errors, waits
with deadlines, and the stepped clock (:meth:`Swarm.step`). See docs/agents.md ("Swarm client",
"Reading the radio", "Stepping the clock").
"""

from __future__ import annotations

import logging
import math
import threading
import time
import uuid
from collections.abc import Callable, Sequence
from typing import TypeVar

import msgspec
import zenoh

from agents.swarm_clients import (
    ROUTE_RETRY_S,
    ClockError,
    CommandRejected,
    CommandTimeout,
    PlumeClient,
    PlumeError,
    SwarmError,
    VehicleCommander,
    WaitTimeout,
)
from agents.swarm_radio import (
    RADIO_KEPT_TICKS,
    RadioKept,
    RadioReadError,
    RadioSent,
    RadioUnavailable,
    kind_of,
)
from swarmbus.closeable import Closeable
from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys, serves_several, vehicle_of_autopilot
from swarmbus.messages import (
    Clock,
    ConcentrationReading,
    LinkStatus,
    Message,
    RadioBatch,
    StepReply,
    StepRequest,
    VehicleState,
    VehicleStatus,
)
from swarmbus.reqrep import BadReply, NoReply, Refused, ask
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, Presence, open_session

__all__ = [
    "ClockError",
    "CommandRejected",
    "CommandTimeout",
    "PlumeClient",
    "PlumeError",
    "RadioReadError",
    "RadioSent",
    "RadioUnavailable",
    "Subscription",
    "Swarm",
    "SwarmError",
    "VehicleCommander",
    "WaitTimeout",
]

log = logging.getLogger(__name__)

T = TypeVar("T")
M = TypeVar("M", bound=Message)
Vec3 = tuple[float, float, float]
CLOCK_CLIENT_PREFIX = "clock-"
# A step's wall-clock deadline (only a dead or stuck physics reaches it): a base and a share
# per granted tick, generous for a large swarm on a loaded machine.
STEP_TIMEOUT_S = 60.0
STEP_TIMEOUT_PER_TICK_S = 0.1


def _check(predicate: Callable[[], T]) -> T | None:
    """``predicate()``, or None when it trips over data not there yet (``None.attr``, a key)."""
    try:
        return predicate()
    except (AttributeError, KeyError, TypeError):
        return None


def _decoded(sample: zenoh.Sample, type_: type[M]) -> M | None:
    """The sample's message, or None (logged) when it is not a valid ``type_``."""
    try:
        return decode(sample.payload.to_bytes(), type_)
    except MessageError as exc:
        log.warning("ignoring %s: %s", sample.key_expr, exc)
        return None


class Subscription:
    def __init__(self, swarm: Swarm, entry: tuple[Callable[..., None] | None, ...]) -> None:
        self._swarm = swarm
        self._entry = entry

    def close(self) -> None:
        self._swarm._unsubscribe(self._entry)


class Swarm(Closeable):
    """A connection to one world's swarm. Use :meth:`connect` as a context manager."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        command_timeout_s: float = 2.0,
        own_session: bool = True,
        radio_kept_ticks: int = RADIO_KEPT_TICKS,
    ) -> None:
        self.session = session
        self.keys = keys
        self.command_timeout_s = command_timeout_s
        self._own_session = own_session
        self._lock = threading.Lock()
        self._states: dict[str, VehicleState] = {}
        self._status: dict[str, VehicleStatus] = {}
        self._readings: dict[str, ConcentrationReading] = {}
        self._radio = RadioKept(radio_kept_ticks)
        self._callbacks: list[tuple[Callable[..., None] | None, ...]] = []
        # What every callback has been given (a stepped client waits for this, see step)
        self._handled_tick: dict[str, int] = {}
        self._handled_status_s: dict[str, float] = {}
        self._handled_radio_tick: dict[str, int] = {}
        self._clock: Clock | None = None
        self._changed = threading.Condition(self._lock)  # a handled message or a clock
        self._clock_name = f"{CLOCK_CLIENT_PREFIX}{uuid.uuid4().hex[:12]}"
        self._clock_token: zenoh.LivelinessToken | None = None
        self._last_step: StepReply | None = None
        self.plume = PlumeClient(session, keys, command_timeout_s)
        self._subs = [
            session.declare_subscriber(
                keys.all_vehicle_states(), self._on(VehicleState, self._states, 0)
            ),
            session.declare_subscriber(
                keys.all_vehicle_status(), self._on(VehicleStatus, self._status, 1)
            ),
            session.declare_subscriber(
                keys.all_vehicle_concentration(),
                self._on(ConcentrationReading, self._readings, 2),
            ),
            session.declare_subscriber(keys.all_vehicle_radio(), self._on_radio),
            session.declare_subscriber(keys.clock(), self._on_clock),
        ]
        self._presence = Presence(session, keys)

    @classmethod
    def connect(
        cls,
        world: str = "default",
        connect: Sequence[str] | None = None,
        *,
        network: NetworkConfig | None = None,
        command_timeout_s: float = 2.0,
        radio_kept_ticks: int = RADIO_KEPT_TICKS,
    ) -> Swarm:
        """Join ``world``. ``connect``: Zenoh endpoints (e.g. ``["tcp/10.0.0.5:7447"]``);
        ``None`` → the default scenario's network (a router on ``tcp/127.0.0.1:7447``).
        ``radio_kept_ticks``: how many ticks of each vehicle's radio messages :meth:`radio`
        keeps."""
        net = network or load_scenario().network
        if connect is not None:
            net = net.with_overrides(connect=list(connect))
        session = open_session(net)
        try:
            return cls(session, Keys(world), command_timeout_s, radio_kept_ticks=radio_kept_ticks)
        except Exception:
            session.close()
            raise

    def close(self) -> None:
        """Leave the bus (and free the clock, when this client held it); idempotent."""
        subs, self._subs = self._subs, []
        if not subs:
            return
        for sub in subs:
            sub.undeclare()
        if self._clock_token is not None:
            self._clock_token.undeclare()  # frees the clock for another client
            self._clock_token = None
        self._presence.close()
        if self._own_session:
            self.session.close()

    # ------------------------------------------------------------------ data
    def _on(self, type_: type[M], cache: dict[str, M], slot: int) -> Callable[[zenoh.Sample], None]:
        def handle(sample: zenoh.Sample) -> None:
            try:
                vid = self.keys.vehicle_id_of(str(sample.key_expr))
                msg = decode(sample.payload.to_bytes(), type_)
            except (MessageError, ValueError) as exc:
                log.warning("ignoring %s: %s", sample.key_expr, exc)
                return
            with self._lock:
                cache[vid] = msg
                callbacks = [c[slot] for c in self._callbacks if c[slot] is not None]
            for cb in callbacks:
                try:
                    cb(msg)  # type: ignore[misc]
                except Exception:
                    log.exception("swarm subscriber callback failed")
            with self._lock:
                if isinstance(msg, VehicleState):
                    self._handled_tick[vid] = max(msg.tick, self._handled_tick.get(vid, -1))
                elif isinstance(msg, VehicleStatus):
                    old = self._handled_status_s.get(vid, -1.0)
                    self._handled_status_s[vid] = max(msg.sim_time_s, old)
                self._changed.notify_all()

        return handle

    def _on_radio(self, sample: zenoh.Sample) -> None:
        batch = _decoded(sample, RadioBatch)
        if batch is None:
            return
        with self._lock:
            sent = self._radio.add(batch)
            callbacks = [c[3] for c in self._callbacks if c[3] is not None] if sent else []
        for message in sent or []:
            for cb in callbacks:
                try:
                    cb(message)
                except Exception:
                    log.exception("swarm subscriber callback failed")
        with self._lock:
            old = self._handled_radio_tick.get(batch.sender, -1)
            self._handled_radio_tick[batch.sender] = max(batch.tick, old)
            self._changed.notify_all()

    def _on_clock(self, sample: zenoh.Sample) -> None:
        clock = _decoded(sample, Clock)
        if clock is None:
            return
        with self._lock:
            if self._clock is None or clock.tick >= self._clock.tick:
                self._clock = clock
            self._changed.notify_all()

    @property
    def vehicles(self) -> list[str]:
        """Ids of the vehicles seen on the bus (an autopilot publishes its status as soon as it
        serves commands; physics publishes states)."""
        with self._lock:
            return sorted(set(self._states) | set(self._status) | set(self._readings))

    def autopilots_alive(self) -> list[str]:
        """Ids of the vehicles whose autopilot token is alive right now (the token of a process
        serving several vehicles is none of theirs: each has its own)."""
        ids = (vehicle_of_autopilot(n) for n in self._presence.alive if not serves_several(n))
        return sorted(vid for vid in ids if vid is not None)

    def state(self, vehicle_id: str) -> VehicleState | None:
        with self._lock:
            return self._states.get(vehicle_id)

    def status(self, vehicle_id: str) -> VehicleStatus | None:
        with self._lock:
            return self._status.get(vehicle_id)

    def reading(self, vehicle_id: str) -> ConcentrationReading | None:
        with self._lock:
            return self._readings.get(vehicle_id)

    def subscribe(
        self,
        on_state: Callable[[VehicleState], None] | None = None,
        on_status: Callable[[VehicleStatus], None] | None = None,
        on_reading: Callable[[ConcentrationReading], None] | None = None,
        on_radio: Callable[[RadioSent], None] | None = None,
    ) -> Subscription:
        """Callbacks for every new state / status / reading / radio message (Zenoh's thread;
        ``on_radio`` gets each message of each new ``vehicle/<id>/radio`` batch, in index
        order); ``.close()``."""
        entry = (on_state, on_status, on_reading, on_radio)
        with self._lock:
            self._callbacks.append(entry)
        return Subscription(self, entry)

    def _unsubscribe(self, entry: tuple[Callable[..., None] | None, ...]) -> None:
        with self._lock:
            if entry in self._callbacks:
                self._callbacks.remove(entry)

    # ------------------------------------------------------------------ radio
    def radio(
        self,
        vehicle_id: str,
        of: type[msgspec.Struct] | None = None,
        since_tick: int = -1,
    ) -> list[RadioSent]:
        """The messages ``vehicle_id``'s behaviour published (``ctx.mailbox.publish``) in its
        steps after ``since_tick``, oldest first, from the batches this client keeps (the last
        ``radio_kept_ticks`` ticks a vehicle); ``of``: only those of that type. Each is a
        :class:`RadioSent` (sender, tick, index, kind, payload); ``.decode(Type)`` gives the
        message. Empty when nothing was published (or the behaviour does not talk)."""
        kind = kind_of(of) if of is not None else None
        with self._lock:
            return self._radio.messages(vehicle_id, since_tick, kind)

    def radio_tick(self, vehicle_id: str) -> int | None:
        """The newest tick whose radio batch from ``vehicle_id`` has arrived (a talking
        behaviour's batch comes every tick, an empty one too); None before the first."""
        with self._lock:
            return self._radio.last_tick(vehicle_id)

    def wait_radio(
        self,
        vehicle_id: str,
        timeout_s: float | None = None,
        *,
        of: type[msgspec.Struct] | None = None,
        since_tick: int = -1,
        sim_timeout_s: float | None = None,
    ) -> list[RadioSent]:
        """:meth:`radio` once it has at least one message (of type ``of``, after
        ``since_tick``); :class:`WaitTimeout` after ``timeout_s`` of wall clock or
        ``sim_timeout_s`` of sim time, as :meth:`wait_until` (which steps a stepped world
        whose clock this client holds)."""
        what = f"a radio message{f' ({of.__qualname__})' if of else ''} from {vehicle_id}"
        return self.wait_until(
            lambda: self.radio(vehicle_id, of, since_tick),
            timeout_s,
            what,
            sim_timeout_s=sim_timeout_s,
        )

    def fetch_radio(self, vehicle_id: str, timeout_s: float | None = None) -> int:
        """Ask ``vehicle_id``'s autopilot for the radio batches it keeps (its last 64 ticks:
        what a client that joined late missed) and keep them; returns how many were new.
        :class:`RadioUnavailable` when nothing answers within ``timeout_s`` (default
        ``command_timeout_s``). Callbacks are not called for them."""
        wait_s = self.command_timeout_s if timeout_s is None else timeout_s
        replies = self.session.get(
            self.keys.vehicle_radio(vehicle_id),
            timeout=wait_s,
            consolidation=zenoh.ConsolidationMode.NONE,  # every kept batch, not the newest
        )
        answered, new = False, 0
        for reply in replies:
            if reply.ok is None:
                continue
            answered = True
            try:
                batch = decode(reply.ok.payload.to_bytes(), RadioBatch)
            except MessageError as exc:
                log.warning("ignoring a radio batch of %s: %s", vehicle_id, exc)
                continue
            with self._lock:
                new += self._radio.add(batch) is not None
                self._changed.notify_all()
        if not answered:
            raise RadioUnavailable(
                f"no answer for {self.keys.vehicle_radio(vehicle_id)} within {wait_s:g} s "
                f"(does the behaviour of {vehicle_id} talk? is its autopilot running?)"
            )
        return new

    def radio_links(self, vehicle_id: str) -> dict[str, LinkStatus] | None:
        """What the radio carried into ``vehicle_id`` so far, by sending peer: the
        ``LinkStatus(sender, delivered, dropped)`` of its latest status (peer states, peer
        samples and behaviour messages). None before its first status; empty with a perfect
        radio on which no behaviour talks."""
        status = self.status(vehicle_id)
        if status is None:
            return None
        return {link.sender: link for link in status.radio}

    def command(self, vehicle_id: str) -> VehicleCommander:
        return VehicleCommander(self.session, self.keys, vehicle_id, self.command_timeout_s)

    def wait_until(
        self,
        predicate: Callable[[], T],
        timeout_s: float | None = None,
        what: str = "",
        poll_s: float = 0.02,
        *,
        sim_timeout_s: float | None = None,
    ) -> T:
        """Poll ``predicate`` until it returns something truthy (returned) or time runs out:
        ``timeout_s`` of wall clock, ``sim_timeout_s`` of simulated time (either or both).

        A predicate that trips over data not there yet (``None.attr``, a missing key) counts
        as "not yet". When this client holds a stepped world's clock, a sim-time wait steps
        the world (:meth:`step_until`, one tick at a time; ``timeout_s`` does not apply)."""
        if timeout_s is None and sim_timeout_s is None:
            raise ValueError("wait_until needs timeout_s (wall clock) or sim_timeout_s (sim time)")
        name = what or getattr(predicate, "__name__", repr(predicate))
        if sim_timeout_s is not None and self.holds_clock:
            return self.step_until(predicate, sim_timeout_s, name)
        deadline = time.monotonic() + timeout_s if timeout_s is not None else math.inf
        sim_deadline = self.sim_time + sim_timeout_s if sim_timeout_s is not None else math.inf
        while True:
            value = _check(predicate)
            if value:
                return value
            if time.monotonic() >= deadline:
                raise WaitTimeout(f"timed out after {timeout_s:g} s waiting for {name}")
            if self._known_sim_time() >= sim_deadline:
                raise WaitTimeout(
                    f"timed out after {sim_timeout_s:g} s of sim time waiting for {name}"
                )
            time.sleep(poll_s)

    # ------------------------------------------------------------------ simulated time
    @property
    def sim_time(self) -> float:
        """The world's simulated time in s: where a stepped world is paused, or the latest
        ``sim/clock`` (waits up to ``command_timeout_s`` for the first one)."""
        with self._lock:
            if self._clock is None and self._last_step is None:
                self._changed.wait_for(lambda: self._clock is not None, self.command_timeout_s)
        known = self._known_sim_time()
        if known < 0.0:
            raise ClockError(
                f"no sim/clock of world {self.keys.world!r} within {self.command_timeout_s:g} s "
                "(is its physics running?)"
            )
        return known

    def _known_sim_time(self) -> float:
        with self._lock:
            times = [-1.0]
            if self._clock is not None:
                times.append(self._clock.sim_time_s)
            if self._last_step is not None:
                times.append(self._last_step.sim_time_s)
        return max(times)

    @property
    def clock(self) -> Clock | None:
        """The latest ``sim/clock`` seen (None before the first)."""
        with self._lock:
            return self._clock

    @property
    def holds_clock(self) -> bool:
        """Whether this client steps the world's clock (since its first accepted step)."""
        return self._last_step is not None

    def step(self, ticks: int = 1, timeout_s: float | None = None) -> StepReply:
        """Advance a stepped world by ``ticks`` control ticks; returns where it paused (tick,
        sim time). On return every state, status and reading of that tick, and the radio batch
        of every vehicle seen talking, has reached this client's caches and callbacks; a
        command sent now takes effect on the next tick.

        The first call takes the world's clock (until :meth:`close`). Raises
        :class:`ClockError` when the world is not in stepped mode, another client holds its
        clock, the world stopped, or the physics does not answer within ``timeout_s`` (default:
        60 s + 0.1 s per tick)."""
        if isinstance(ticks, bool) or not isinstance(ticks, int) or ticks < 1:
            raise ValueError(f"step: ticks must be an integer >= 1, got {ticks!r}")
        if self._clock_token is None:
            # Our token tells the physics when we are gone (the clock is free again).
            key = self.keys.node_health(self._clock_name)
            self._clock_token = self.session.liveliness().declare_token(key)
            # Whose statuses to wait for after each step: the autopilots alive now, not only
            # those whose tokens a just-opened session has heard of.
            self._presence.sync(timeout_s=self.command_timeout_s)
        wait_s = (
            timeout_s
            if timeout_s is not None
            else (STEP_TIMEOUT_S + ticks * STEP_TIMEOUT_PER_TICK_S)
        )
        reply = self._request_step(StepRequest(client=self._clock_name, ticks=ticks), wait_s)
        self._last_step = reply
        self._await_handled(reply)
        return reply

    def _request_step(self, step: StepRequest, wait_s: float) -> StepReply:
        """The physics' answer to ``step`` (asked again while nothing serves ``clock/step``: a
        session just opened may not know the route yet); raises :class:`ClockError`."""
        first = time.monotonic()
        while True:
            asked = time.monotonic()
            outcome = ask(self.session, self.keys.clock_step(), step, StepReply, wait_s).outcome()
            waited = time.monotonic() - asked
            if not isinstance(outcome, NoReply):
                break
            if waited >= wait_s or asked - first >= self.command_timeout_s:
                break
            time.sleep(ROUTE_RETRY_S)
        if isinstance(outcome, StepReply):
            return outcome
        if self._last_step is None and self._clock_token is not None:
            self._clock_token.undeclare()
            self._clock_token = None
        world = self.keys.world
        if isinstance(outcome, Refused):
            raise ClockError(f"step of world {world!r} refused ({outcome.field}): {outcome.reason}")
        if isinstance(outcome, BadReply):
            raise ClockError(f"step of world {world!r}: {outcome}")
        when = f"within {wait_s:g} s" if waited >= wait_s else "(nobody serves clock/step)"
        raise ClockError(
            f"no answer to a step of {step.ticks} tick(s) {when}: "
            f"is the physics of world {world!r} running?"
        )

    def _await_handled(self, reply: StepReply) -> None:
        """Until this tick's states, (live autopilots') statuses and radio batches (of the
        vehicles seen talking) went through the caches and callbacks: they travel from other
        processes than the step's reply, so they may come after it, and each subscriber's
        callbacks run on their own thread. Readings are published before their status."""
        alive = set(self.autopilots_alive())

        def stale() -> list[str]:
            late = {v for v, t in self._handled_tick.items() if t < reply.tick}
            late |= {v for v in alive if self._handled_status_s.get(v, -1.0) < reply.sim_time_s}
            late |= {
                v for v, t in self._handled_radio_tick.items() if v in alive and t < reply.tick
            }
            return sorted(late)

        with self._lock:
            if not self._changed.wait_for(lambda: not stale(), self.command_timeout_s):
                log.warning(
                    "tick %d: no state or status of that tick from %s within %g s",
                    reply.tick,
                    ", ".join(stale()),
                    self.command_timeout_s,
                )

    def step_until(
        self, predicate: Callable[[], T], timeout_sim_s: float, what: str = "", ticks: int = 1
    ) -> T:
        """Step ``ticks`` at a time until ``predicate`` returns something truthy (returned);
        :class:`WaitTimeout` after ``timeout_sim_s`` of simulated time. The predicate is
        checked before the first step and after every step, on that tick's data."""
        name = what or getattr(predicate, "__name__", repr(predicate))
        start_s = self._last_step.sim_time_s if self._last_step is not None else self.sim_time
        while True:
            value = _check(predicate)
            if value:
                return value
            reply = self.step(ticks)
            if reply.sim_time_s - start_s >= timeout_sim_s - 1e-9:
                value = _check(predicate)
                if value:
                    return value
                raise WaitTimeout(
                    f"timed out after {timeout_sim_s:g} s of sim time waiting for {name} "
                    f"(tick {reply.tick}, t={reply.sim_time_s:.3f} s)"
                )
