"""Catching up after a router outage (swarmbus.catchup): a publisher keeps its last samples and
puts them again when a subscriber matches it again while the router is away or just back; not
otherwise. Real sessions (clients of a router on loopback)."""

from __future__ import annotations

import threading
import time

import zenoh

from swarmbus.catchup import CatchUpPublisher, Resender, RouterOutage
from swarmbus.session import NetworkConfig, open_session
from tests.support.procs import Network, wait_until

KEY = "test/catchup/readings"


class _Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_an_outage_lasts_while_the_router_is_away_and_after_s_after_its_return() -> None:
    clock = _Clock()
    outage = RouterOutage(clock, after_s=10.0)
    assert not outage.on()
    outage.router(True)  # its token at start: no outage
    assert not outage.on()
    outage.router(False)
    clock.now += 60.0  # away for as long as it takes
    assert outage.on()
    outage.router(True)
    clock.now += 9.9
    assert outage.on()
    clock.now += 0.2
    assert not outage.on()


class _Collect:
    def __init__(self) -> None:
        self.got: list[bytes] = []
        self.lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.got.append(sample.payload.to_bytes())

    def now(self) -> list[bytes]:
        with self.lock:
            return list(self.got)


def test_a_subscriber_back_during_an_outage_gets_the_kept_samples_again(
    network: tuple[Network, zenoh.Session],
) -> None:
    net, _ = network
    client = NetworkConfig(mode="client", connect=[net.endpoint], listen=[])
    outage = RouterOutage(after_s=3600.0)
    with open_session(client) as pub_side, open_session(client) as sub_side:
        pub = CatchUpPublisher(pub_side, KEY, depth=3)
        first = _Collect()
        sub = sub_side.declare_subscriber(KEY, first)
        wait_until(lambda: pub.matching, 10.0, "the first subscriber matched")
        for k in range(4):
            pub.put(b"s%d" % k)
        wait_until(lambda: len(first.now()) == 4, 10.0, "4 samples")
        sub.undeclare()
        wait_until(lambda: not pub.matching, 10.0, "no subscriber")
        pub.put(b"s4")  # nobody receives it

        # outside an outage a new subscriber starts from what is published from then on
        late = _Collect()
        sub = sub_side.declare_subscriber(KEY, late)
        wait_until(lambda: pub.matching, 10.0, "a subscriber outside an outage")
        assert pub.catch_up(outage) == 0
        sub.undeclare()
        wait_until(lambda: not pub.matching, 10.0, "no subscriber again")
        pub.put(b"s5")

        # during an outage the one that matches again gets the last 3 samples put
        outage.router(False)
        back = _Collect()
        sub = sub_side.declare_subscriber(KEY, back)
        wait_until(lambda: pub.matching, 10.0, "a subscriber back during the outage")
        assert pub.catch_up(outage) == 3
        assert pub.catch_up(outage) == 0  # once per return
        wait_until(lambda: len(back.now()) == 3, 10.0, "the kept samples")
        assert back.now() == [b"s3", b"s4", b"s5"]
        assert late.now() == []
        sub.undeclare()
        pub.close()


def test_kept_samples_are_bounded_in_bytes_and_put_again_by_the_worker_at_its_rate(
    network: tuple[Network, zenoh.Session],
) -> None:
    """A publisher keeps the newest samples that fit in ``max_bytes``; a catch-up hands them
    to the Resender, whose worker puts them no faster than its rate (bursts of 200)."""
    net, _ = network
    client = NetworkConfig(mode="client", connect=[net.endpoint], listen=[])
    outage = RouterOutage(after_s=3600.0)
    resender = Resender("test-catch-up", rate_per_s=2000.0)
    try:
        with open_session(client) as pub_side, open_session(client) as sub_side:
            pub = CatchUpPublisher(pub_side, KEY, depth=5000, resender=resender, max_bytes=10_000)
            for k in range(3000):
                pub.put(b"%09d" % k)  # 9 bytes each: the newest 1 111 fit in 10 000
            assert pub.kept_bytes == 1111 * 9
            outage.router(False)
            back = _Collect()
            sub = sub_side.declare_subscriber(KEY, back)
            wait_until(lambda: pub.matching, 10.0, "a subscriber back during the outage")
            t0 = time.monotonic()
            assert pub.catch_up(outage) == 1111
            assert resender.wait_idle(30.0)
            took = time.monotonic() - t0
            # 1 111 puts at 2 000/s: the worker waited after each burst of 200 but the last
            assert took >= 1000 / 2000.0
            assert resender.puts == 1111
            want = [b"%09d" % k for k in range(3000 - 1111, 3000)]
            wait_until(lambda: len(back.now()) == 1111, 10.0, "the kept samples")
            assert back.now() == want
            sub.undeclare()
            pub.close()
    finally:
        resender.close()
