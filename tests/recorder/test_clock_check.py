"""The recorder's bound is Zenoh's: uhlc's ``UHLC_MAX_DELTA_MS`` or its 500 ms default; a
value Zenoh's clock would panic on is refused in one line before any session opens."""

from __future__ import annotations

import pytest

from recorder.clock_check import zenoh_clock_bound_s
from tests.support.procs import run_cli


@pytest.mark.parametrize(
    ("value", "bound_s"),
    [(None, 0.5), ("2000", 2.0), ("750", 0.75), ("0", 0.0)],
)
def test_the_bound_is_uhlc_max_delta(value: str | None, bound_s: float) -> None:
    environ = {} if value is None else {"UHLC_MAX_DELTA_MS": value}
    assert zenoh_clock_bound_s(environ) == bound_s


@pytest.mark.parametrize("value", ["abc", "1.5", "-3", " 750", ""])
def test_a_bad_uhlc_max_delta_is_one_line_before_zenoh_starts(value: str) -> None:
    result = run_cli(
        ["status", "--connect", "tcp/127.0.0.1:9"], env={"UHLC_MAX_DELTA_MS": value}, timeout_s=60
    )
    assert result.returncode == 2, result.stderr[-2000:]
    assert "Traceback" not in result.stderr and "panic" not in result.stderr, result.stderr
    assert result.stderr.strip().splitlines()[-1] == (
        f"plumeswarm: error: UHLC_MAX_DELTA_MS={value!r}: expected a whole number of "
        "milliseconds (how far ahead of a host's clock Zenoh takes a timestamp; default 500)"
    )
