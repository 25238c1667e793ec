"""Opening Zenoh sessions from our config, and presence by liveliness tokens.

Defaults are hermetic: multicast scouting off, and listen/connect endpoints only on loopback
unless the configuration says otherwise. Every process announces itself with a liveliness token
under ``node/<name>/health``; :class:`Presence` tells who is alive from those tokens.
"""

from __future__ import annotations

import json
import logging
import os
import socket
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from typing import Annotated, Any, Literal

import msgspec
import zenoh

from swarmbus.keys import Keys

log = logging.getLogger(__name__)

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
Endpoint = Annotated[str, msgspec.Meta(pattern=r"^(tcp|udp|tls|quic|unixsock-stream)/.+$")]


class NetworkConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How a process joins the Zenoh network."""

    mode: Literal["peer", "client", "router"] = "peer"
    connect: list[Endpoint] = msgspec.field(default_factory=lambda: [DEFAULT_ROUTER])
    listen: list[Endpoint] = msgspec.field(default_factory=lambda: ["tcp/127.0.0.1:0"])
    multicast_scouting: bool = False
    low_latency: bool = False
    tls: dict[str, str] | None = None  # raw zenoh transport/link/tls settings
    access_control: dict[str, Any] | None = None  # raw zenoh access_control section

    def with_overrides(
        self,
        *,
        mode: str | None = None,
        connect: list[str] | None = None,
        listen: list[str] | None = None,
    ) -> NetworkConfig:
        return msgspec.structs.replace(
            self,
            mode=mode or self.mode,
            connect=list(connect) if connect is not None else self.connect,
            listen=list(listen) if listen is not None else self.listen,
        )


def zenoh_config(net: NetworkConfig) -> zenoh.Config:
    """A ``zenoh.Config`` for ``net``."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(net.mode))
    conf.insert_json5("connect/endpoints", json.dumps(list(net.connect)))
    conf.insert_json5("listen/endpoints", json.dumps(list(net.listen)))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(net.multicast_scouting))
    if net.low_latency:
        conf.insert_json5("transport/unicast/lowlatency", "true")
        conf.insert_json5("transport/unicast/qos/enabled", "false")
    if net.tls:
        for key, value in net.tls.items():
            conf.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    if net.access_control:
        conf.insert_json5("access_control", json.dumps(net.access_control))
    return conf


def open_session(net: NetworkConfig) -> zenoh.Session:
    """Open a session; use it as a context manager (``with open_session(net) as s``)."""
    return zenoh.open(zenoh_config(net))


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (zenoh cannot report the port bound for 0)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def announce(session: zenoh.Session, keys: Keys, node_name: str) -> zenoh.LivelinessToken:
    """Declare this process's liveliness token ``node/<name>/health``; undeclare to leave."""
    return session.liveliness().declare_token(keys.node_health(node_name))


class Presence:
    """Who is alive, learned from liveliness tokens (PUT on arrival, DELETE on departure).

    ``on_change(name, alive)`` is called from Zenoh's thread on every arrival and departure.
    """

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        on_change: Callable[[str, bool], None] | None = None,
    ) -> None:
        self._keys = keys
        self._alive: set[str] = set()
        self._lock = threading.Condition()
        self._on_change = on_change
        self._sub = session.liveliness().declare_subscriber(
            keys.all_node_health(), self._handle, history=True
        )

    def _handle(self, sample: zenoh.Sample) -> None:
        try:
            name = self._keys.node_name_of(str(sample.key_expr))
        except ValueError:
            log.warning("ignoring liveliness token %s", sample.key_expr)
            return
        alive = sample.kind == zenoh.SampleKind.PUT
        with self._lock:
            if alive:
                self._alive.add(name)
            else:
                self._alive.discard(name)
            self._lock.notify_all()
        if self._on_change is not None:
            self._on_change(name, alive)

    @property
    def alive(self) -> frozenset[str]:
        with self._lock:
            return frozenset(self._alive)

    def wait_for(self, predicate: Callable[[frozenset[str]], bool], timeout_s: float) -> bool:
        """Block until ``predicate(alive)`` holds or the timeout passes; returns whether it held."""
        with self._lock:
            return self._lock.wait_for(lambda: predicate(frozenset(self._alive)), timeout_s)

    def close(self) -> None:
        self._sub.undeclare()


@contextmanager
def node_session(
    net: NetworkConfig, keys: Keys, node_name: str
) -> Iterator[tuple[zenoh.Session, zenoh.LivelinessToken]]:
    """Open a session and announce ``node_name``; both are closed on exit."""
    with open_session(net) as session:
        token = announce(session, keys, node_name)
        try:
            yield session, token
        finally:
            with suppress(zenoh.ZError):  # session already closing
                token.undeclare()


def process_identity() -> tuple[int, str]:
    return os.getpid(), socket.gethostname()
