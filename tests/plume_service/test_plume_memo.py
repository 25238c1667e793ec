"""The plume's point-query handler computes a repeated payload once (lockstep: N equal asks)."""

from __future__ import annotations

from typing import Any

from plume_service.service import _handler
from swarmbus.codec import decode, encode
from swarmbus.messages import PlumeQuery, PlumeValues


class _Payload:
    def __init__(self, data: bytes) -> None:
        self.data = data

    def to_bytes(self) -> bytes:
        return self.data


class _Query:
    key_expr = "plume/concentration"

    def __init__(self, data: bytes) -> None:
        self.payload = _Payload(data)
        self.replies: list[bytes] = []

    def reply(self, key: Any, data: bytes) -> None:
        self.replies.append(data)


def test_equal_payloads_are_served_once_with_equal_replies() -> None:
    calls: list[PlumeQuery] = []

    def serve(q: PlumeQuery) -> PlumeValues:
        calls.append(q)
        return PlumeValues(values_g_m3=[float(len(calls))], sim_time_s=q.sim_time_s)

    handle = _handler(PlumeQuery, serve, "concentration", memo=True)
    a = encode(PlumeQuery(points_enu_m=[(1.0, 2.0, 3.0)], sim_time_s=0.5))
    b = encode(PlumeQuery(points_enu_m=[(1.0, 2.0, 3.5)], sim_time_s=0.5))
    queries = [_Query(a), _Query(a), _Query(b), _Query(a)]
    for q in queries:
        handle(q)  # type: ignore[arg-type]
    assert len(calls) == 3  # a, (a cached), b, a again
    values = [decode(q.replies[0], PlumeValues).values_g_m3 for q in queries]
    assert values == [[1.0], [1.0], [2.0], [3.0]]
