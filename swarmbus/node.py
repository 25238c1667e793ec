"""What every process of plumeswarm shares: its config object and its runtime shell.

A role's entry point is ``main(ctx: NodeContext) -> int``. It opens a :class:`NodeRuntime`
(``with NodeRuntime(ctx, role="physics") as rt:``), which opens the Zenoh session, publishes
its :class:`~swarmbus.messages.NodeHealth` (up → ready → stopping) and turns SIGINT/SIGTERM
into ``rt.stop`` being set, so the role's loop ends cleanly. ``rt.ready()`` declares the node's
liveliness token once the role serves.
"""

from __future__ import annotations

import logging
import signal
import threading
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from types import FrameType, TracebackType

import zenoh

from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import NodeHealth, NodeState
from swarmbus.scenario import Scenario
from swarmbus.session import NetworkConfig, open_session, process_identity

log = logging.getLogger(__name__)


def package_version() -> str:
    try:
        return version("plumeswarm")
    except PackageNotFoundError:
        return "0+unknown"


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

    def __init__(self, ctx: NodeContext, role: str, install_signals: bool = True) -> None:
        self.ctx = ctx
        self.role = role
        self.keys = ctx.keys
        self.stop = threading.Event()
        self._install_signals = install_signals
        self._session: zenoh.Session | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._health_pub: zenoh.Publisher | None = None
        self._state = NodeState.UP

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
        self.publish_health(NodeState.UP)
        return self

    def publish_health(
        self, state: NodeState | None = None, sim_time_s: float | None = None, detail: str = ""
    ) -> None:
        if state is not None:
            self._state = state
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
                    sim_time_s=sim_time_s,
                    detail=detail[:1000],
                )
            )
        )

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
