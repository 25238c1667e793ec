"""Bounded messages: a process refuses a message larger than ``[network]
max_message_size_bytes`` with a log line naming its key, its size and the limit; Zenoh drops
one over 4 times the limit (its transport limit) unlogged; the link goes on; a message that
does not decode is refused with a log line naming its key, rate-limited per key.
Real sessions on loopback (a router and its clients or peers)."""

from __future__ import annotations

import logging
import threading
from typing import Any

import msgspec
import pytest
import zenoh

from swarmbus.codec import Refusals, decode_or_none, encode
from swarmbus.messages import Clock, SpeedMode
from swarmbus.session import NetworkConfig, open_session, payload_or_none
from tests.support.procs import Network, wait_until

KEY = "test/bounds/payload"
MIB = 1024 * 1024


class _Sizes:
    """The payload sizes a subscriber's handler accepted (through :func:`payload_or_none`)."""

    def __init__(self, log: logging.Logger) -> None:
        self.log = log
        self.sizes: list[int] = []
        self.lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "a payload", self.log)
        if data is not None:
            with self.lock:
                self.sizes.append(len(data))

    def now(self) -> list[int]:
        with self.lock:
            return list(self.sizes)


def _matching(pub: zenoh.Publisher) -> bool:
    status: Any = pub.matching_status  # a MatchingStatus (the stub says bool)
    return bool(status.matching)


@pytest.mark.parametrize("mode", ["client", "peer"])
def test_a_message_over_the_limit_is_refused_with_its_key_and_beyond_the_transport_dropped(
    network: tuple[Network, zenoh.Session], mode: str, caplog: pytest.LogCaptureFixture
) -> None:
    net, _ = network  # the router: the default limits
    limit = MIB
    log = logging.getLogger(f"tests.bounds.size.{mode}")  # its own rate limit
    # The rogue's own limit is Zenoh's 1 GiB: only the receiving side can refuse.
    rogue = NetworkConfig(
        mode=mode,  # type: ignore[arg-type]
        connect=[net.endpoint],
        max_message_size_bytes=2**30,
        shared_memory=False,
    )
    ours = NetworkConfig(mode=mode, connect=[net.endpoint], max_message_size_bytes=limit)  # type: ignore[arg-type]
    # the receiver's session is opened last: the limit payload_or_none applies is its own
    with open_session(rogue) as sender, open_session(ours) as receiver:
        got = _Sizes(log)
        sub = receiver.declare_subscriber(KEY, got)
        pub = sender.declare_publisher(KEY, congestion_control=zenoh.CongestionControl.BLOCK)
        wait_until(lambda: _matching(pub), 10.0, "the subscriber matched")
        over = limit + 1024  # reaches the process (under 4 × the limit), refused there
        beyond = 4 * limit + 1024  # over Zenoh's transport limit: dropped unlogged
        with caplog.at_level(logging.WARNING, logger=log.name):
            pub.put(b"u" * (limit - 1024))  # the control: just under the limit
            pub.put(b"x" * over)
            pub.put(b"y" * beyond)
            pub.put(b"marker")
            wait_until(lambda: 6 in got.now(), 30.0, "the marker after the large payloads")
        assert got.now() == [limit - 1024, 6]
        lines = [r.getMessage() for r in caplog.records if r.name == log.name]
        assert lines == [
            f"ignoring a payload of {over} bytes on {KEY}: over [network] "
            f"max_message_size_bytes {limit}"
        ]
        pub.put(b"after!!")  # the link is still up
        wait_until(lambda: 7 in got.now(), 10.0, "a message after the refused ones")
        sub.undeclare()
        pub.undeclare()


def test_the_limit_is_checked_when_the_scenario_is_read() -> None:
    with pytest.raises(msgspec.ValidationError, match="max_message_size_bytes"):
        msgspec.convert({"max_message_size_bytes": 1000}, NetworkConfig)


class _Clock:
    def __init__(self) -> None:
        self.now = 50.0

    def __call__(self) -> float:
        return self.now


def test_refusals_log_a_key_once_then_at_most_once_a_period_with_the_count(
    caplog: pytest.LogCaptureFixture,
) -> None:
    log = logging.getLogger("tests.bounds.refusals")
    clock = _Clock()
    refusals = Refusals(log, period_s=5.0, clock=clock)
    with caplog.at_level(logging.WARNING, logger=log.name):
        for _ in range(1000):
            refusals.refuse("w/vehicle/uav1/state", "state on w/vehicle/uav1/state", "bad")
        refusals.refuse("w/sim/tick", "tick on w/sim/tick", "bad")  # another key: its own line
        clock.now += 4.9
        refusals.refuse("w/vehicle/uav1/state", "state on w/vehicle/uav1/state", "bad")
        clock.now += 0.2
        refusals.refuse("w/vehicle/uav1/state", "state on w/vehicle/uav1/state", "worse")
    lines = [r.getMessage() for r in caplog.records]
    assert lines == [
        "ignoring state on w/vehicle/uav1/state: bad",
        "ignoring tick on w/sim/tick: bad",
        "ignoring state on w/vehicle/uav1/state: worse (1000 more refused on "
        "w/vehicle/uav1/state since)",
    ]
    assert refusals.refused == {"w/vehicle/uav1/state": 1002, "w/sim/tick": 1}


def test_decode_or_none_names_the_key_of_a_message_that_does_not_decode(
    caplog: pytest.LogCaptureFixture,
) -> None:
    log = logging.getLogger("tests.bounds.decode")
    good = Clock(
        tick=3, sim_time_s=0.5, mode=SpeedMode.LOCKSTEP, speed_factor=1.0, real_time_factor=1.0
    )
    with caplog.at_level(logging.WARNING, logger=log.name):
        assert decode_or_none(encode(good), Clock, "a clock", log, "w/sim/clock") == good
        assert decode_or_none(b"\x00" * 100_000, Clock, "a clock", log, "w/sim/clock") is None
    [record] = caplog.records
    assert record.getMessage().startswith("ignoring a clock on w/sim/clock: invalid Clock")
