"""Making sure a recorder hears a publisher before the publisher starts (or before it stops).

Zenoh may lose a subscriber's first messages while routes are being set up, even after
liveliness says the subscriber is there. A publisher that must not lose any message therefore
waits for the recorder's liveliness token, then re-publishes its own ``NodeHealth`` until the
recorder acknowledges it (the recorder publishes ``detail = "heard <name> <state>"`` on its own
health key for every health message it records). Since Zenoh keeps a session's messages in
order, an acknowledged ``STOPPING`` also means everything published before it was recorded.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import zenoh

from swarmbus.codec import MessageError, decode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys
from swarmbus.messages import NodeHealth, NodeState
from swarmbus.session import Presence, payload_or_none

log = logging.getLogger(__name__)


class RecorderNotListening(PlumeswarmError, TimeoutError):
    """The recorder did not acknowledge in time."""


def ack_detail(node_name: str, state: NodeState) -> str:
    return f"heard {node_name} {state}"


def wait_until_recorded(
    session: zenoh.Session,
    keys: Keys,
    node_name: str,
    state: NodeState,
    publish_own_health: Callable[[], None],
    *,
    recorder: str = "recorder",
    timeout_s: float = 30.0,
    period_s: float = 0.1,
) -> None:
    """Publish our health (state ``state``) until ``recorder`` acknowledges it, or raise."""
    expected = ack_detail(node_name, state)
    heard = threading.Event()

    def on_recorder_health(sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "recorder health", log)
        if data is None:
            return
        try:
            health = decode(data, NodeHealth)
        except MessageError:
            return
        if health.detail == expected:
            heard.set()

    deadline = time.monotonic() + timeout_s
    sub = session.declare_subscriber(keys.node_health(recorder), on_recorder_health)
    presence = Presence(session, keys)
    try:
        if not presence.wait_for(lambda alive: recorder in alive, timeout_s):
            raise RecorderNotListening(f"no recorder {recorder!r} on the bus after {timeout_s} s")
        while True:
            publish_own_health()
            if heard.wait(period_s):
                return
            if time.monotonic() > deadline:
                raise RecorderNotListening(
                    f"recorder {recorder!r} did not acknowledge {node_name!r} ({state}) "
                    f"within {timeout_s} s"
                )
    finally:
        presence.close()
        sub.undeclare()
