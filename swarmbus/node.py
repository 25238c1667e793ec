"""What every process of plumeswarm shares: its config object and its runtime shell.

A role's entry point is ``main(ctx: NodeContext) -> int``. It opens a :class:`NodeRuntime`
(``with NodeRuntime(ctx, role="physics") as rt:``), which opens the Zenoh session, publishes
its :class:`~swarmbus.messages.NodeHealth` (up → ready → stopping) and turns SIGINT/SIGTERM
into ``rt.stop`` being set, so the role's loop ends cleanly (``for t0 in rt.paced(rate_hz):``
runs one at a fixed rate until then). ``rt.ready()`` declares the node's liveliness token once
the role serves.

Every health carries the node's scenario hash (:func:`~swarmbus.scenario.scenario_hash`). A
lockstep participant (``check_scenario_of="physics"``) compares it with the physics's: a
participant started with a different scenario is refused (``rt.refusal``, one line naming both
hashes, logged) and stops; its ``main`` then exits non-zero. The physics refuses it too.
"""

from __future__ import annotations

import functools
import logging
import signal
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from types import FrameType, TracebackType

import zenoh

from swarmbus.codec import decode_or_none, encode
from swarmbus.keys import Keys
from swarmbus.messages import NodeHealth, NodeState
from swarmbus.scenario import Scenario, scenario_hash
from swarmbus.session import NetworkConfig, open_session, payload_or_none, process_identity

log = logging.getLogger(__name__)
HEALTH_PERIOD_S = 1.0


@functools.cache
def package_version() -> str:
    """Read once: importlib.metadata parses the METADATA file on every call (~1 ms)."""
    try:
        return version("plumeswarm")
    except PackageNotFoundError:
        return "0+unknown"


class StopEvent(threading.Event):
    """Set by SIGINT/SIGTERM. ``wait()`` without a timeout wakes up every 0.25 s: the kernel may
    deliver a signal to one of Zenoh's threads, and Python runs its handler only when the main
    thread wakes, so a main thread blocked for good in ``wait()`` would never see the signal."""

    def wait(self, timeout: float | None = None) -> bool:
        if timeout is not None:
            return super().wait(timeout)
        while not super().wait(0.25):
            pass
        return True


@dataclass(frozen=True)
class NodeContext:
    """The validated configuration a role's ``main`` receives (built by the CLI or launcher)."""

    scenario: Scenario
    network: NetworkConfig
    name: str
    vehicle_ids: tuple[str, ...] = ()
    options: dict[str, str] = field(default_factory=dict)

    @property
    def keys(self) -> Keys:
        return Keys(self.scenario.world.name)


class NodeRuntime:
    """Session + liveliness token + health + stop signal for one process."""

    def __init__(
        self,
        ctx: NodeContext,
        role: str,
        install_signals: bool = True,
        check_scenario_of: str | None = None,
    ) -> None:
        self.ctx = ctx
        self.scenario_hash = scenario_hash(ctx.scenario)
        self._check_of = check_scenario_of  # the node whose scenario hash must equal ours
        self._check_sub: zenoh.Subscriber[None] | None = None
        self.refusal: str | None = None  # why this process was refused (a different scenario)
        self.role = role
        self.keys = ctx.keys
        self.stop = StopEvent()
        self._install_signals = install_signals
        self._session: zenoh.Session | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._health_pub: zenoh.Publisher | None = None
        self._state = NodeState.UP
        self._sim_time_s: float | None = None
        self._detail = ""
        self._heartbeat: threading.Thread | None = None
        self._heartbeat_stop = threading.Event()

    @property
    def session(self) -> zenoh.Session:
        if self._session is None:
            raise RuntimeError("NodeRuntime is not open")
        return self._session

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        log.info("%s: signal %d, stopping", self.ctx.name, signum)
        self.stop.set()

    def __enter__(self) -> NodeRuntime:
        if self._install_signals and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, self._on_signal)
            signal.signal(signal.SIGTERM, self._on_signal)
        self._session = open_session(self.ctx.network)
        self._health_pub = self._session.declare_publisher(self.keys.node_health(self.ctx.name))
        if self._check_of is not None:
            self._check_sub = self._session.declare_subscriber(
                self.keys.node_health(self._check_of), self._on_checked_health
            )
        self.publish_health(NodeState.UP)
        self._heartbeat = threading.Thread(target=self._beat, name="health", daemon=True)
        self._heartbeat.start()
        return self

    def _on_checked_health(self, sample: zenoh.Sample) -> None:
        what = f"health of {self._check_of}"
        data = payload_or_none(sample, what, log)
        health = None if data is None else decode_or_none(data, NodeHealth, what, log)
        if health is None or not health.scenario or health.scenario == self.scenario_hash:
            return
        if self.refusal is None:
            self.refusal = (
                f"refused by {health.name}: scenario hash {self.scenario_hash} here, "
                f"{health.scenario} at {health.name} (started with a different scenario file)"
            )
            log.error("%s: %s", self.ctx.name, self.refusal)
        self.stop.set()

    def _beat(self) -> None:
        # NodeHealth is also periodic, so `plumeswarm status` learns PIDs/hosts within a period.
        while not self._heartbeat_stop.wait(HEALTH_PERIOD_S):
            try:
                self.publish_health()
            except zenoh.ZError:
                return

    def publish_health(
        self, state: NodeState | None = None, sim_time_s: float | None = None, detail: str = ""
    ) -> None:
        if state is not None:
            self._state = state
        if sim_time_s is not None:
            self._sim_time_s = sim_time_s
        if detail:
            self._detail = detail
        if self._health_pub is None:
            return
        pid, host = process_identity()
        self._health_pub.put(
            encode(
                NodeHealth(
                    name=self.ctx.name,
                    role=self.role,
                    state=self._state,
                    version=package_version(),
                    pid=pid,
                    host=host,
                    sim_time_s=self._sim_time_s,
                    detail=self._detail[:1000],
                    scenario=self.scenario_hash,
                    vehicles=list(self.ctx.vehicle_ids),
                )
            )
        )

    def paced(self, rate_hz: float) -> Iterator[float]:
        """A role's loop at ``rate_hz`` until stopped: yields each round's start (monotonic
        seconds); the next round starts a period after this one began, at once if it ran late."""
        period = 1.0 / rate_hz
        while not self.stop.is_set():
            t0 = time.monotonic()
            yield t0
            self.stop.wait(max(0.0, period - (time.monotonic() - t0)))

    def ready(self) -> None:
        """Declare the liveliness token: the node is alive and serving from here on.

        Declared only now, after the role's publishers, subscribers and queryables, so a peer
        that sees the token also finds what the node serves.
        """
        if self._token is None:
            self._token = self.session.liveliness().declare_token(
                self.keys.node_health(self.ctx.name)
            )
        self.publish_health(NodeState.READY)
        log.info("%s ready", self.ctx.name)

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._heartbeat_stop.set()
        if self._check_sub is not None:
            self._check_sub.undeclare()
        if self._heartbeat is not None:
            self._heartbeat.join(timeout=2.0)
        try:
            self.publish_health(NodeState.STOPPING)
            if self._token is not None:
                self._token.undeclare()
        except zenoh.ZError:
            pass
        finally:
            if self._session is not None:
                self._session.close()
            self._session = None
