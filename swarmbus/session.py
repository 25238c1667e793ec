"""Opening Zenoh sessions from our config, and presence by liveliness tokens.

Defaults are hermetic: multicast scouting off, and listen/connect endpoints only on loopback
unless the configuration says otherwise. Every process announces itself with a liveliness token
under ``node/<name>/health``; :class:`Presence` tells who is alive from those tokens.
"""

from __future__ import annotations

import json
import logging
import os
import random
import socket
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager, suppress
from typing import Annotated, Any, Literal

import msgspec
import zenoh

from swarmbus.codec import refusals
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import JOIN_FLUSH, ROUTER_ADMIN, Keys

log = logging.getLogger(__name__)

DEFAULT_ROUTER = "tcp/127.0.0.1:7447"
# ``ZENOH_RUNTIME`` for a process that should run Zenoh on ONE thread (receive, send, network,
# application): a sample is received, handled and answered with no hand-over between threads.
# Set it in the environment before the process opens its first session.
SINGLE_THREAD_RUNTIME = (
    "(app: (worker_threads: 1), acc: (handover: app), tx: (handover: app),"
    " rx: (handover: app), net: (handover: app))"
)
# Reconnection (Zenoh's own): a session whose link to its router (or a peer it was told to
# connect to) breaks tries again every 100 ms, doubling up to 1 s, for ever; when it is back,
# Zenoh declares its subscribers, queryables and liveliness tokens again on the new link. A
# killed router restarted on the same endpoints is rejoined within about a second of its start.
# How long a new peer waits for its links to the other peers (join_peers).
PEER_JOIN_TIMEOUT_S = 2.0
CONNECT_RETRY = {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2.0}
Endpoint = Annotated[str, msgspec.Meta(pattern=r"^(tcp|udp|tls|quic|unixsock-stream)/.+$")]
# The largest message a process takes (``[network] max_message_size_bytes``): a larger one is
# refused by the receiving process before it is decoded or recorded, with a warning naming its
# key, its size and the limit (:func:`payload_or_none`). Well above our largest legitimate
# messages: a 100 000-point plume query (≈ 2.8 MB), a 1 m plume mesh of the seed domain
# (≈ 0.5 MB), a tick of 1024 vehicles (≈ 350 KB). A 0.1 m mesh (≈ 54 MB) needs more.
DEFAULT_MAX_MESSAGE_BYTES = 32 * 1024 * 1024
# Zenoh's transport limit (``transport/link/rx/max_message_size``; Zenoh's own default is 1 GiB)
# is this multiple of it: a message up to that size reaches the process, which refuses it with
# a line; a larger one is dropped by Zenoh when it reassembles the fragments, with no line of
# ours. The transport limit bounds the memory one message in transit takes: up to about 1.6
# times its size while Zenoh reassembles it (docs/bus.md, "Message size").
TRANSPORT_MESSAGE_FACTOR = 4
MIN_MAX_MESSAGE_BYTES = 64 * 1024  # below this a tick of a few hundred vehicles would not fit


class NetworkConfigError(PlumeswarmError, ValueError):
    """The network configuration cannot be used (e.g. a TLS file is missing): one line why."""


class TlsConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """Mutual TLS on every ``tls/`` link: this process's identity (certificate and key, PEM) and
    the CA that every peer's certificate must be signed by. The certificate's common name is
    the identity the access-control list matches on."""

    root_ca: Annotated[
        str,
        msgspec.Meta(description="PEM file of the CA every peer's certificate must be signed by."),
    ]
    cert: Annotated[str, msgspec.Meta(description="PEM file of this process's certificate.")]
    key: Annotated[str, msgspec.Meta(description="PEM file of this process's private key.")]
    verify_name: Annotated[
        bool,
        msgspec.Meta(description="The certificate of the host connected to must name its address."),
    ] = True


class NetworkConfig(msgspec.Struct, frozen=True, kw_only=True, forbid_unknown_fields=True):
    """How a process joins the Zenoh network."""

    mode: Annotated[
        Literal["peer", "client", "router"],
        msgspec.Meta(description="Zenoh mode of the processes: peer, client or router."),
    ] = "peer"
    connect: Annotated[
        list[Endpoint], msgspec.Meta(description="Zenoh endpoints to connect to (the router).")
    ] = msgspec.field(default_factory=lambda: [DEFAULT_ROUTER])
    listen: Annotated[list[Endpoint], msgspec.Meta(description="Zenoh endpoints to listen on.")] = (
        msgspec.field(default_factory=lambda: ["tcp/127.0.0.1:0"])
    )
    multicast_scouting: Annotated[
        bool, msgspec.Meta(description="Find peers by multicast (off: only the endpoints given).")
    ] = False
    low_latency: Annotated[
        bool, msgspec.Meta(description="Zenoh's low-latency transport (no batching).")
    ] = False
    shared_memory: Annotated[
        bool,
        msgspec.Meta(
            description=(
                "Zenoh's shared-memory transport between processes on one host (messages of 3 KB "
                "and more); off: far less resident memory with many processes."
            )
        ),
    ] = True
    tls: Annotated[TlsConfig | None, msgspec.Meta(description="Mutual TLS on every tls/ link.")] = (
        None
    )
    access_control: Annotated[
        dict[str, Any] | None, msgspec.Meta(description="Zenoh's access_control section, as is.")
    ] = None
    max_message_size_bytes: Annotated[
        int,
        msgspec.Meta(
            ge=MIN_MAX_MESSAGE_BYTES,
            le=2**30,
            description=(
                "Largest message a process takes (bytes); a larger one is refused with a "
                "warning naming its key (up to 4 times this; beyond, Zenoh drops it unlogged)."
            ),
        ),
    ] = DEFAULT_MAX_MESSAGE_BYTES

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


# Zenoh's bound on how far ahead of a receiver's clock a sample's timestamp may be (its hybrid
# logical clock's delta): uhlc reads it from this variable, in milliseconds (default 500), and
# panics on a value that is not a whole number (docs/reliability.md, "Clocks of the hosts").
CLOCK_DELTA_VARIABLE = "UHLC_MAX_DELTA_MS"


def check_clock_delta(environ: Mapping[str, str] = os.environ) -> None:
    """Refuse, in one line, a ``UHLC_MAX_DELTA_MS`` that Zenoh's clock would panic on."""
    raw = environ.get(CLOCK_DELTA_VARIABLE)
    if raw is not None and not (raw.isascii() and raw.isdigit() and int(raw) < 2**64):
        raise NetworkConfigError(
            f"{CLOCK_DELTA_VARIABLE}={raw!r}: expected a whole number of milliseconds (how far "
            f"ahead of a host's clock Zenoh takes a timestamp; default 500)"
        )


def zenoh_config(net: NetworkConfig) -> zenoh.Config:
    """A ``zenoh.Config`` for ``net``."""
    check_clock_delta()
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(net.mode))
    conf.insert_json5("connect/endpoints", json.dumps(list(net.connect)))
    conf.insert_json5("listen/endpoints", json.dumps(list(net.listen)))
    conf.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    # A peer opens even when its router is not up yet and joins it once it is; a client must
    # reach its router at open (one clear error, e.g. a refused TLS certificate), and after
    # that reconnects like a peer. Neither gives up on a lost link.
    conf.insert_json5("connect/exit_on_failure", json.dumps(net.mode == "client"))
    conf.insert_json5("scouting/multicast/enabled", json.dumps(net.multicast_scouting))
    # Every sample carries its publisher's (HLC) time: recordings keep when a message was
    # published, not only when the recorder got it, and replay reproduces that timing.
    conf.insert_json5("timestamping/enabled", "true")
    conf.insert_json5("transport/shared_memory/enabled", json.dumps(net.shared_memory))
    transport_limit = TRANSPORT_MESSAGE_FACTOR * net.max_message_size_bytes
    conf.insert_json5("transport/link/rx/max_message_size", json.dumps(transport_limit))
    if net.low_latency:
        conf.insert_json5("transport/unicast/lowlatency", "true")
        conf.insert_json5("transport/unicast/qos/enabled", "false")
    if net.tls is not None:
        for key, value in tls_settings(net.tls).items():
            conf.insert_json5(f"transport/link/tls/{key}", json.dumps(value))
    if net.access_control:
        conf.insert_json5("access_control", json.dumps(net.access_control))
    if net.mode == "router":
        # Read-only: a new peer asks its router which peers it must connect to (join_peers).
        conf.insert_json5("adminspace/enabled", "true")
    return conf


def tls_settings(tls: TlsConfig) -> dict[str, str | bool]:
    """Zenoh's ``transport/link/tls`` for ``tls``: the same identity when listening and
    connecting, and client certificates required (mTLS) on every listener."""
    check_tls_files(tls)
    return {
        "root_ca_certificate": tls.root_ca,
        "listen_certificate": tls.cert,
        "listen_private_key": tls.key,
        "connect_certificate": tls.cert,
        "connect_private_key": tls.key,
        "enable_mtls": True,
        "verify_name_on_connect": tls.verify_name,
    }


def check_tls_files(tls: TlsConfig) -> None:
    """:class:`NetworkConfigError` naming the first TLS file that is missing, unreadable or not
    PEM (Zenoh itself would only say that no endpoint could be reached)."""
    for kind, path, marker in (
        ("CA certificate", tls.root_ca, b"-----BEGIN CERTIFICATE-----"),
        ("certificate", tls.cert, b"-----BEGIN CERTIFICATE-----"),
        ("private key", tls.key, b"PRIVATE KEY-----"),
    ):
        try:
            with open(path, "rb") as f:
                data = f.read()
        except FileNotFoundError:
            raise NetworkConfigError(f"TLS {kind} {path}: no such file") from None
        except IsADirectoryError:
            raise NetworkConfigError(f"TLS {kind} {path}: is a directory") from None
        except OSError as exc:
            raise NetworkConfigError(f"TLS {kind} {path}: {exc.strerror or exc}") from None
        if marker not in data:
            raise NetworkConfigError(f"TLS {kind} {path}: not PEM ({marker.decode()} missing)")


_message_limit = DEFAULT_MAX_MESSAGE_BYTES  # of the session this process opened last


def message_limit() -> int:
    """The ``[network] max_message_size_bytes`` of the session this process opened last."""
    return _message_limit


def payload_or_none(
    message: zenoh.Sample | zenoh.Query, what: object, log: logging.Logger
) -> bytes | None:
    """The payload of a received sample or query (empty if it has none), or None after a
    warning on ``log`` when it is over :func:`message_limit`: ``ignoring <what> of <n> bytes on
    <key>: over [network] max_message_size_bytes <limit>`` (rate-limited per key,
    :class:`~swarmbus.codec.Refusals`). The size is read without copying the payload."""
    payload = message.payload
    if payload is None:
        return b""
    size = len(payload)
    limit = _message_limit
    if size > limit:
        key = str(message.key_expr)
        refusals(log).refuse(
            key,
            f"{what} of {size} bytes on {key}",
            f"over [network] max_message_size_bytes {limit}",
            "size",
        )
        return None
    return payload.to_bytes()


def open_session(net: NetworkConfig) -> zenoh.Session:
    """Open a session; use it as a context manager (``with open_session(net) as s``). A peer
    returns once it is connected to the peers its router knows (:func:`join_peers`)."""
    session = zenoh.open(zenoh_config(net))
    global _message_limit
    _message_limit = net.max_message_size_bytes
    if net.mode == "peer":
        join_peers(session, PEER_JOIN_TIMEOUT_S)
    return session


def join_peers(session: zenoh.Session, timeout_s: float) -> bool:
    """Wait until ``session`` (a peer) is connected to every peer of the routers it is
    connected to, and has their declarations; returns whether it got there in time.

    Zenoh opens a peer's session once its router's declarations are in; the links to the other
    peers (which data between peers takes: routers do not relay it) come a moment later, from
    the router's gossip. A put made before them reaches no other peer, so a restarted process's
    first reading or state would be lost. The router's admin space names its peers; a
    liveliness query then crosses every new link after the declarations sent on it."""
    deadline = time.monotonic() + timeout_s
    want = _router_peers(session, timeout_s) - {str(session.info.zid())}
    while not want <= {str(z) for z in session.info.peers_zid()}:
        if time.monotonic() >= deadline:
            log.warning(
                "not connected to %d of the router's peers after %.1f s",
                len(want - {str(z) for z in session.info.peers_zid()}),
                timeout_s,
            )
            return False
        time.sleep(0.005)
    for _ in session.liveliness().get(JOIN_FLUSH, timeout=max(0.1, deadline - time.monotonic())):
        pass
    return True


def _router_peers(session: zenoh.Session, timeout_s: float) -> set[str]:
    """The peers of the routers ``session`` is connected to, from their admin space (none
    where it cannot be read, e.g. an access-control list that does not admit it)."""
    peers: set[str] = set()
    for router in session.info.routers_zid():
        for reply in session.get(ROUTER_ADMIN.replace("*", str(router)), timeout=timeout_s):
            if reply.ok is None:
                continue
            with suppress(ValueError, TypeError, AttributeError):
                info = json.loads(reply.ok.payload.to_string())
                peers |= {
                    str(s["peer"]) for s in info.get("sessions", []) if s.get("whatami") == "peer"
                }
    return peers


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port that was free a moment ago (zenoh cannot report the port bound for 0)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def free_udp_block(count: int, tries: int = 200) -> int:
    """A base port such that base … base+count-1 are free UDP ports on loopback right now."""
    for _ in range(tries):
        base = random.randint(20000, 60000 - count)
        socks: list[socket.socket] = []
        try:
            for port in range(base, base + count):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", port))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no free block of UDP ports")


def announce(session: zenoh.Session, keys: Keys, node_name: str) -> zenoh.LivelinessToken:
    """Declare this process's liveliness token ``node/<name>/health``; undeclare to leave."""
    return session.liveliness().declare_token(keys.node_health(node_name))


class Presence:
    """Who is alive, learned from liveliness tokens (PUT on arrival, DELETE on departure).

    ``on_change(name, alive)`` is called from Zenoh's thread on every arrival and departure
    (once per change: a token reported twice, by the history and by :meth:`sync`, is one).
    """

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        on_change: Callable[[str, bool], None] | None = None,
    ) -> None:
        self._session = session
        self._keys = keys
        self._alive: set[str] = set()
        self._heard: set[str] = set()  # names the subscriber reported (arrival or departure)
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
            self._heard.add(name)
            changed = (name in self._alive) != alive
            if alive:
                self._alive.add(name)
            else:
                self._alive.discard(name)
            self._lock.notify_all()
        if changed and self._on_change is not None:
            self._on_change(name, alive)

    def sync(self, timeout_s: float = 2.0) -> None:
        """Learn who is alive right now, before going on (a liveliness query, answered when
        every reachable node replied or ``timeout_s`` passed).

        The subscriber's ``history`` delivers the tokens present at its declaration
        asynchronously, so a caller that must know them before it acts (the physics, before
        its first tick) asks here. A name the subscriber already reported is left to it: its
        departure may have arrived before this answer."""
        done = threading.Event()
        # A callback, not a channel: a swarm has more tokens than a channel's default capacity.
        self._session.liveliness().get(
            self._keys.all_node_health(),
            zenoh.handlers.Callback(self._on_sync_reply, done.set),
            timeout=timeout_s,
        )
        done.wait(timeout_s + 1.0)

    def _on_sync_reply(self, reply: zenoh.Reply) -> None:
        if reply.ok is None:
            return
        try:
            name = self._keys.node_name_of(str(reply.ok.key_expr))
        except ValueError:
            return
        with self._lock:
            if name in self._heard:
                return
            self._heard.add(name)
            self._alive.add(name)
            self._lock.notify_all()
        if self._on_change is not None:
            self._on_change(name, True)

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
