"""rmw_zenoh's wire format (ROS 2 Kilted, rmw_zenoh_cpp 0.6; the same in Jazzy's since 0.2.4):
what a ROS 2 node on Zenoh sees.

- A topic ``/uav1/odom`` of type ``nav_msgs/msg/Odometry`` in ROS domain ``D`` is the key
  expression ``D/uav1/odom/nav_msgs::msg::dds_::Odometry_/RIHS01_<sha256>``: the name without its
  leading slash, the DDS type name, the type's RIHS01 hash (REP-2011).
- Payloads are CDR (little-endian, with its 4-byte encapsulation header), serialised by
  ``rosbags`` from the distribution's own message definitions.
- Every publication carries an attachment: its sequence number (int64, from 1), the source
  timestamp in ns (int64, wall clock) and the publisher's 16-byte GID, in zenoh-ext's
  serialisation (two 8-byte little-endian integers, then the GID as a length-prefixed byte
  sequence) — the layout rmw_zenoh uses since 0.6.0 (Kilted; backported to Jazzy's 0.2.4).
- The graph is a set of liveliness tokens under ``@ros2_lv/D/``: one per node
  (``@ros2_lv/D/<zid>/<nid>/<nid>/NN/<enclave>/<namespace>/<name>``) and one per publisher,
  subscription, service or client (``.../<nid>/<id>/MP|MS|SS|SC/<enclave>/<namespace>/<name>/
  <topic>/<type>/<hash>/<qos>``), where ``/`` inside a name is written ``%`` and an empty
  namespace or enclave is ``%``.
"""

from __future__ import annotations

import functools
import hashlib
import itertools
from dataclasses import dataclass, field
from typing import Any

import zenoh
import zenoh.ext
from rosbags.typesys import Stores, get_typestore
from rosbags.typesys.store import Typestore

from swarmbus.errors import PlumeswarmError

DISTRIBUTION = "kilted"
ADMIN_SPACE = "@ros2_lv"
# The QoS of a token whose every policy is rmw_zenoh's default (reliable, volatile, keep last
# with the default depth): each field is left empty when it equals the default.
DEFAULT_QOS = "::,:,:,:,,"


class WireError(PlumeswarmError, ValueError):
    """A payload that is not a valid message of the topic's type."""


@functools.cache
def typestore() -> Typestore:
    """The message definitions of the distribution (Kilted) that ``rosbags`` ships."""
    return get_typestore(Stores.ROS2_KILTED)


def dds_type_name(msgtype: str) -> str:
    """``geometry_msgs/msg/Twist`` → ``geometry_msgs::msg::dds_::Twist_``."""
    package, kind, name = msgtype.split("/")
    return f"{package}::{kind}::dds_::{name}_"


@functools.cache
def type_hash(msgtype: str) -> str:
    """The RIHS01 hash of ``msgtype`` (REP-2011), as ``ros2 topic info -v`` prints it."""
    return str(typestore().hash_rihs01(msgtype))


def mangle(name: str) -> str:
    """A name inside a liveliness token: ``/`` → ``%`` (an empty name is ``%``)."""
    return name.replace("/", "%") if name else "%"


def topic_key(domain_id: int, topic: str, msgtype: str) -> str:
    return f"{domain_id}/{topic.strip('/')}/{dds_type_name(msgtype)}/{type_hash(msgtype)}"


def encode(message: object, msgtype: str) -> bytes:
    return bytes(typestore().serialize_cdr(message, msgtype))


def decode(payload: bytes, msgtype: str) -> Any:
    """The message, or :class:`WireError` (a truncated or foreign payload)."""
    try:
        return typestore().deserialize_cdr(payload, msgtype)
    except Exception as exc:  # rosbags raises struct.error, IndexError, ValueError, …
        raise WireError(f"not a {msgtype} CDR payload ({type(exc).__name__}: {exc})") from None


def attachment(sequence: int, timestamp_ns: int, gid: bytes) -> bytes:
    return zenoh.ext.z_serialize(
        (zenoh.ext.Int64(sequence), zenoh.ext.Int64(timestamp_ns), gid)
    ).to_bytes()


@dataclass(frozen=True)
class NodeName:
    domain_id: int
    zid: str
    node_id: int
    name: str
    namespace: str = "/"
    enclave: str = "/"

    def node_token(self) -> str:
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{self.node_id}/NN/"
            f"{mangle(self.enclave)}/{mangle(self.namespace)}/{self.name}"
        )

    def entity_token(self, entity_id: int, kind: str, topic: str, msgtype: str) -> str:
        return (
            f"{ADMIN_SPACE}/{self.domain_id}/{self.zid}/{self.node_id}/{entity_id}/{kind}/"
            f"{mangle(self.enclave)}/{mangle(self.namespace)}/{self.name}/{mangle(topic)}/"
            f"{dds_type_name(msgtype)}/{type_hash(msgtype)}/{DEFAULT_QOS}"
        )


def gid_of(token: str) -> bytes:
    """An entity's 16-byte GID: a hash of its liveliness token (unique as the token is)."""
    return hashlib.blake2b(token.encode(), digest_size=16).digest()


@dataclass
class Graph:
    """One ROS 2 node on a Zenoh session: its token and its entities' tokens."""

    session: zenoh.Session
    node: NodeName
    _ids: itertools.count[int] = field(default_factory=lambda: itertools.count(1))
    _tokens: list[zenoh.LivelinessToken] = field(default_factory=list)

    def declare_node(self) -> None:
        self._tokens.append(self.session.liveliness().declare_token(self.node.node_token()))

    def declare_entity(self, kind: str, topic: str, msgtype: str) -> bytes:
        """Announce a publisher (``MP``) or subscription (``MS``); its GID."""
        token = self.node.entity_token(next(self._ids), kind, topic, msgtype)
        self._tokens.append(self.session.liveliness().declare_token(token))
        return gid_of(token)

    def close(self) -> None:
        for token in self._tokens:
            token.undeclare()
        self._tokens.clear()
