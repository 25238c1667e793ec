"""The viewer in headless Chromium: the page shows the scene, and its tree holds vehicles and plume.

The real plume node answers ``plume/mesh``; stand-ins in the test process play physics
(``sim/tick``) and the autopilots' readings. The screenshot is kept as docs/viewer.png when
PLUMESWARM_SAVE_SCREENSHOT=1.
"""

from __future__ import annotations

import itertools
import math
import os
import shutil
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import matplotlib.image
import numpy as np
import zenoh

from deploy.busview import BusView
from swarmbus.codec import encode
from swarmbus.messages import (
    SimTick,
    VehicleState,
)
from swarmbus.scenario import load_scenario
from tests.support.browser import NEEDS_CHROMIUM, chromium_page, wait_for_scene_nodes
from tests.support.messages_samples import reading, vehicle_state
from tests.support.procs import REPO, Network, NodeProcs, keys_for, repeating, wait_until

pytestmark = NEEDS_CHROMIUM


def state(vid: str, tick: int, pos: tuple[float, float, float]) -> VehicleState:
    return vehicle_state(vid, tick, pos, attitude_xyzw=(0.0, 0.0, math.sin(0.2), math.cos(0.2)))


@contextmanager
def flying_stand_ins(session: zenoh.Session) -> Iterator[None]:
    """Physics' ticks and the autopilots' readings: vehicles circling inside the plume."""
    keys = keys_for()
    sc = load_scenario()
    ticks = itertools.count(1)

    def fly() -> None:
        tick = next(ticks)
        states = []
        for i, v in enumerate(sc.vehicles):
            a = tick / 60 + i * 2.0
            pos = (30.0 + 10 * math.cos(a), 6.0 * (i - 1) + 6 * math.sin(a), 10.0)
            states.append(state(v.id, tick, pos))
            sample = reading(v.id, tick / 120, pos, 0.05 * (i + 1))
            session.put(keys.vehicle_concentration(v.id), encode(sample))
        tick_msg = SimTick(tick=tick, sim_time_s=tick / 120, control_dt_s=1 / 120, states=states)
        session.put(keys.tick(), encode(tick_msg))

    with repeating(0.02, fly):
        yield


SCENE_NAMES = ["vehicles", "plume", "level_0", "level_1", "trails", "readings", "source"]


def test_viewer_page_shows_vehicles_and_plume(
    network: tuple[Network, zenoh.Session], tmp_path: Path
) -> None:
    net, _ = network
    sc = load_scenario()
    names = SCENE_NAMES + [v.id for v in sc.vehicles]
    shot = tmp_path / "viewer.png"
    with (
        _client(net) as session,
        flying_stand_ins(session),
        NodeProcs(net, log_dir=tmp_path) as procs,
    ):
        view = BusView(session, keys_for())
        procs.start("plume", name="plume")
        procs.start("viewer", name="viewer")
        health = wait_until(
            lambda: (h := view.snapshot().health.get("viewer")) and "plume=3/3" in h.detail and h,
            90.0,
            "the viewer's health saying all 3 plume levels arrived",
        )
        url = health.detail.split()[0].removeprefix("url=")
        assert url.startswith("http://127.0.0.1:") and url.endswith("/static/")
        # Explicit waits on the page's own state (no virtual-time budget: software WebGL on a
        # loaded 2-core machine renders at its own pace, and a budget can stall behind it).
        with chromium_page(url, 1024, 640) as page:
            # meshcat's control panel lists every scene node it received, one element each.
            wait_for_scene_nodes(page, names, 120_000)
            html = page.content()
            # A few frames after the scene is complete, then the picture.
            page.wait_for_timeout(1_000)
            page.screenshot(path=str(shot), timeout=120_000)
        view.close()
    # The page's scene tree holds every node (the wait above would have timed out otherwise;
    # the static check here reads the same document once more).
    for name in names:
        assert f">{name}<" in html, f"{name!r} not in the page's scene tree"
    # Not blank: many distinct colours, and the translucent plume's purples/reds are there.
    img = matplotlib.image.imread(shot)[:, :, :3]
    assert img.shape[:2] == (640, 1024)
    colours = np.unique((img * 255).astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 500, f"only {len(colours)} colours: blank page?"
    assert img.std() > 0.05
    if os.environ.get("PLUMESWARM_SAVE_SCREENSHOT") == "1":
        shutil.copy(shot, REPO / "docs" / "viewer.png")


@contextmanager
def _client(net: Network) -> Iterator[zenoh.Session]:
    from swarmbus.session import open_session

    with open_session(net.client) as session:
        yield session
