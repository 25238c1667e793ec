from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from tests.support.physics_rig import Watch
from tests.support.procs import Network, NodeProcs, zenoh_network


@pytest.fixture
def network() -> Iterator[tuple[Network, zenoh.Session]]:
    """A Zenoh router on a free loopback port, owned by the test process."""
    with zenoh_network() as pair:
        yield pair


@pytest.fixture
def rig(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> Iterator[tuple[NodeProcs, Watch]]:
    """Node processes logging to ``tmp_path`` and a watch of every tick and clock on the test's
    session (tests/support/physics_rig.py); both stopped after the test."""
    net, session = network
    watch = Watch(session)
    procs = NodeProcs(net, log_dir=tmp_path)
    yield procs, watch
    procs.stop_all()
    watch.close()
