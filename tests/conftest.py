from __future__ import annotations

from collections.abc import Iterator

import pytest
import zenoh

from tests.support.procs import Network, zenoh_network


@pytest.fixture
def network() -> Iterator[tuple[Network, zenoh.Session]]:
    """A Zenoh router on a free loopback port, owned by the test process."""
    with zenoh_network() as pair:
        yield pair
