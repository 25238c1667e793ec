"""The bounds that docs/reliability.md's "Bounded resources" table states are the ones the code
holds: each row's numbers are read from the table and compared with the constants and defaults
the processes run with (the behaviour at a bound is tested with small bounds beside the code:
tests/swarmbus/test_bounds.py, test_catchup.py, tests/sim_world/test_tick_out.py,
tests/recorder/test_recorder_bounds.py, tests/system/test_faults_bounds.py)."""

from __future__ import annotations

import inspect
import re
from pathlib import Path

from agents.autopilot_node import READINGS_KEPT
from recorder.node import RecorderOptions
from sim_world.tick_out import CATCH_UP_MAX_BYTES, CATCH_UP_OUTAGE_TICKS, CATCH_UP_TICKS
from swarmbus.catchup import RESEND_RATE_PER_S, CatchUpPublisher
from swarmbus.codec import REFUSAL_LOG_PERIOD_S
from swarmbus.session import NetworkConfig

DOC = Path(__file__).resolve().parents[2] / "docs" / "reliability.md"
MIB = 2**20


def _rows() -> dict[str, str]:
    """The table under "## Bounded resources": first cell → the rest of the row, with the
    spaces inside numbers (``4 096``) removed."""
    text = DOC.read_text()
    section = text.split("## Bounded resources", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("|") and len(cells) == 3 and not set(cells[0]) <= {"-"}:
            rows[cells[0]] = re.sub(r"(?<=\d)[ \u00a0\u202f](?=\d{3}\b)", "", " | ".join(cells[1:]))
    return rows


def test_the_bounded_resources_table_states_the_bounds_the_code_holds() -> None:
    rows = _rows()
    message = rows["One message"]
    assert f"default {NetworkConfig().max_message_size_bytes // MIB} MiB" in message, message
    refusal = rows["A message that does not decode"]
    assert f"one line per {REFUSAL_LOG_PERIOD_S:g} s with the count" in refusal, refusal
    queue = rows["The recorder's queue"]
    options = RecorderOptions()
    assert f"`max_backlog_bytes` ({options.max_backlog_bytes // MIB} MiB)" in queue, queue
    ticks = rows["The physics' ticks kept for a catch-up after a router outage"]
    want = (
        f"{CATCH_UP_TICKS} ticks; during an outage {CATCH_UP_OUTAGE_TICKS} ticks and "
        f"{CATCH_UP_MAX_BYTES // MIB} MiB of encoded ticks"
    )
    assert want in ticks, ticks
    readings = rows["An autopilot's readings kept for a catch-up"]
    default_bytes = inspect.signature(CatchUpPublisher).parameters["max_bytes"].default
    assert f"{READINGS_KEPT} per vehicle and {default_bytes // MIB} MiB" in readings, readings
    resends = rows["The catch-up's re-sends"]
    assert f"at most {RESEND_RATE_PER_S:.0f} puts/s" in resends, resends
