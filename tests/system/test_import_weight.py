"""A process loads only what it runs: the heavy optional modules stay out of every node."""

from __future__ import annotations

import subprocess
import sys

import pytest

# Loaded only where they are used: scipy (wind meander, filaments, infotaxis), mcubes (plume
# meshes, which pulls in scipy.ndimage), pymap3d (global mission items; the gateway converts
# every position with it), the Swarm client.
HEAVY = ("scipy", "mcubes", "pymap3d", "agents.swarm")


@pytest.mark.parametrize(
    ("entry", "allowed"),
    [
        ("agents.autopilot_node", ()),
        ("sim_world.physics_node", ()),
        ("plume_service.service", ()),
        ("gcs_bridge.gateway", ("pymap3d",)),
    ],
)
def test_a_node_process_does_not_import_heavy_optional_modules(
    entry: str, allowed: tuple[str, ...]
) -> None:
    # What `plumeswarm node ROLE` imports: the command line, then the role's entry module.
    code = (
        f"import sys, plumeswarm.cli, {entry}\n"
        f"print(' '.join(m for m in {HEAVY!r} if m in sys.modules and m not in {allowed!r}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.strip() == "", f"{entry} imports {out.stdout.strip()}"


def test_the_lazy_names_still_resolve() -> None:
    code = (
        "from agents import Swarm, WaitTimeout\n"
        "from plume_service.mesh import isosurface\n"
        "import plume_service.filament as f\n"
        "print(Swarm.__name__, WaitTimeout.__name__)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert out.stdout.split() == ["Swarm", "WaitTimeout"]
