"""The refusal log's own rules, on a clock the test moves and a real pipe: the first refusal of
each (identity, action, key) at once, repeats once a window with their count, a burst budget,
and every line that is not the ACL's trace passed on untouched (the end-to-end check over mTLS
is tests/deploy/test_tls_acl_refusals.py)."""

from __future__ import annotations

import logging
import os

import pytest

from swarmbus.refusals import Refusal, RefusalLog, _Reader, parse_refusal
from tests.support.fake_clock import FakeClock

A = Refusal("physics.sim", "put", "plumeswarm/default/vehicle/uav1/status")
B = Refusal("physics.sim", "put", "plumeswarm/default/field/sample")


def test_a_repeated_refusal_is_one_line_a_window_with_its_count() -> None:
    clock = FakeClock(0.0)
    rl = RefusalLog(repeat_s=60.0, burst=10, clock=clock)
    assert rl.record(A) == [f"access control refused put on {A.key} from physics.sim"]
    for t in (1.0, 2.0, 59.0):
        clock.now = t
        assert rl.record(A) == []
    assert rl.record(B) != []  # another key is not a repeat
    clock.now = 61.0
    assert rl.record(A) == [
        f"access control refused put on {A.key} from physics.sim (3 more since 61 s ago)"
    ]
    assert rl.total == 6


def test_a_flood_of_distinct_keys_is_held_to_the_burst_then_one_line_a_second() -> None:
    clock = FakeClock(0.0)
    rl = RefusalLog(repeat_s=60.0, burst=3, clock=clock)
    flood = [Refusal("ros2.gcs", "put", f"k/{i}") for i in range(10)]
    logged = [line for r in flood for line in rl.record(r)]
    assert len(logged) == 3  # the burst; 7 held back
    clock.now = 1.0  # one token back
    lines = rl.record(Refusal("ros2.gcs", "put", "k/10"))
    assert lines == [
        "access control refused put on k/10 from ros2.gcs",
        "access control: 7 more refusals not logged (rate limit)",
    ]


# Lines as Zenoh 1.10's trace writes them (colours and all), with a line of the process between.
TRACE = (
    b"\x1b[2m2026-11-29T10:31:24.783633Z\x1b[0m \x1b[35mTRACE\x1b[0m rx-1 ThreadId(10) "
    b"\x1b[2mzenoh::net::routing::interceptor::access_control\x1b[0m\x1b[2m:\x1b[0m 3ff0 on "
    b"Interface(lo)+CertCommonName(physics.sim)+Transport(Tls)+3ff0 is unauthorized to Put "
    b"(ingress) on plumeswarm/default/field/sample\n"
    b"a line the process printed\n"
    b"2026-11-29T10:31:24.784011Z TRACE rx-1 ThreadId(10) zenoh::net::routing::interceptor: "
    b"Msg intercepted!\n"
    b"2026-11-29T10:31:24.784075Z TRACE rx-1 ThreadId(11) zenoh::net::routing::interceptor::"
    b"access_control: Using cached result: 3ff0 is authorized to Put (ingress) on a/b\n"
    b"2026-11-29T10:31:24.784075Z TRACE rx-1 ThreadId(12) zenoh::net::routing::interceptor::"
    b"access_control: Using cached result: 3ff0 is unauthorized to Liveliness Token (ingress) "
    b"on plumeswarm/default/node/physics/health\n"
    b"2026-11-29T10:31:24.784077Z TRACE rx-1 ThreadId(12) zenoh::net::routing::interceptor: "
    b"Msg intercepted!\n"
    b"the last line, unterminated"
)


def test_the_reader_logs_the_drops_and_passes_every_other_line_on(
    caplog: pytest.LogCaptureFixture,
) -> None:
    trace_r, trace_w = os.pipe()
    out_r, out_w = os.pipe()
    os.write(trace_w, TRACE)
    os.close(trace_w)
    with caplog.at_level(logging.WARNING, logger="swarmbus.refusals"):
        _Reader(trace_r, out_w, RefusalLog()).run()
    os.close(out_w)
    assert os.read(out_r, 65536) == b"a line the process printed\nthe last line, unterminated"
    os.close(trace_r)
    os.close(out_r)
    assert [r.getMessage() for r in caplog.records] == [
        "access control refused put on plumeswarm/default/field/sample from physics.sim",
        "access control refused liveliness token on plumeswarm/default/node/physics/health "
        "from physics.sim",  # the cached decision names the zenoh id only: learnt above
    ]


def test_an_unknown_sender_is_named_by_its_zenoh_id_and_egress_is_not_a_refusal() -> None:
    line = "Using cached result: 9a9a is unauthorized to Query (ingress) on a/b"
    assert parse_refusal(line, {}) == Refusal("zenoh id 9a9a", "query", "a/b")
    assert parse_refusal(line.replace("ingress", "egress"), {}) is None


@pytest.mark.parametrize(
    ("said", "action"),
    [
        ("Declare Liveliness Subscriber", "liveliness subscriber"),
        ("Declare/Undeclare Queryable", "queryable"),
        ("Undeclare Queryable", "undeclare queryable"),
        ("Liveliness Query", "liveliness query"),
    ],
)
def test_zenohs_names_of_declarations_are_the_documented_actions(said: str, action: str) -> None:
    line = f"3ff0 on CertCommonName(ros2.gcs) is unauthorized to {said} (ingress) on a/b"
    assert parse_refusal(line, {}) == Refusal("ros2.gcs", action, "a/b")
