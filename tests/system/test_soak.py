"""Soak: 32 vehicles fly looping square missions for 10 minutes of SIM time under
``plumeswarm up --headless --vehicles-per-process 8`` (4 autopilot processes of 8 vehicles).

Checked: no tick lost — every tick from the first to the last seen by this test's subscriber,
contiguous, and physics's own count of participants dropped for a missed deadline is 0 — no
process restarted, every vehicle still flying its mission; and the RSS of every process (with
its children) flat within 10 %: the median over a window after warm-up against the median over
the last window. Numbers are printed (-s). ``PLUMESWARM_SOAK_SIM_S`` shortens the run (trials).
"""

from __future__ import annotations

import os
import re
import statistics
import threading
import time
from pathlib import Path

import msgspec
import psutil
import pytest
import zenoh

from deploy.scaling import scale_scenario, write_scenario
from plumeswarm.bench.scale import drive
from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Clock,
    FlightMode,
    NodeHealth,
    VehicleStatus,
)
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from tests.support.procs import REPO
from tests.support.upstack import plumeswarm_up

pytestmark = [pytest.mark.soak, pytest.mark.timeout(5400)]

VEHICLES = 32
PER_PROCESS = 8
SIM_S = 600.0
WINDOW_FRACTION = 0.1  # warm-up, and each RSS window, as a fraction of the run's sim time
RSS_TOLERANCE = 0.10
SAMPLE_PERIOD_S = 2.0


class TickOnly(msgspec.Struct):
    tick: int


_tick_decoder = msgspec.msgpack.Decoder(TickOnly)


class Observer:
    """Ticks (contiguity), the clock, physics's health and every vehicle's status."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self.lock = threading.Lock()
        self.first_tick = self.last_tick = -1
        self.ticks_seen = 0
        self.tick_gaps: list[tuple[int, int]] = []  # (last seen, next seen)
        self.clock: Clock | None = None
        self.physics: NodeHealth | None = None
        self.status: dict[str, VehicleStatus] = {}
        self._subs = [
            session.declare_subscriber(keys.tick(), self._on_tick),
            session.declare_subscriber(keys.clock(), self._on_clock),
            session.declare_subscriber(keys.node_health("physics"), self._on_physics),
            session.declare_subscriber(keys.all_vehicle_status(), self._on_status),
        ]

    def _on_tick(self, sample: zenoh.Sample) -> None:
        tick = _tick_decoder.decode(sample.payload.to_bytes()).tick
        with self.lock:
            if self.last_tick >= 0 and tick != self.last_tick + 1:
                self.tick_gaps.append((self.last_tick, tick))
            if self.first_tick < 0:
                self.first_tick = tick
            self.last_tick = tick
            self.ticks_seen += 1

    def _on_clock(self, sample: zenoh.Sample) -> None:
        self.clock = decode(sample.payload.to_bytes(), Clock)

    def _on_physics(self, sample: zenoh.Sample) -> None:
        self.physics = decode(sample.payload.to_bytes(), NodeHealth)

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            st = decode(sample.payload.to_bytes(), VehicleStatus)
        except MessageError:
            return
        with self.lock:
            self.status[st.vehicle_id] = st

    def sim_time_s(self) -> float:
        return self.clock.sim_time_s if self.clock is not None else 0.0

    def physics_dropped(self) -> int:
        assert self.physics is not None, "no physics health heard"
        found = re.search(r"\bdropped (\d+)", self.physics.detail)
        assert found, f"no dropped count in physics's health: {self.physics.detail!r}"
        return int(found[1])

    def close(self) -> None:
        for s in self._subs:
            s.undeclare()


def rss_of(pid: int) -> int:
    """RSS of a process and its children (bytes); 0 when it is gone."""
    try:
        p = psutil.Process(pid)
        return sum(q.memory_info().rss for q in [p, *p.children(recursive=True)])
    except psutil.Error:
        return 0


def test_soak_32_vehicles_ten_sim_minutes(tmp_path: Path) -> None:
    sim_s = float(os.environ.get("PLUMESWARM_SOAK_SIM_S", SIM_S))
    base = load_scenario(REPO / "swarmbus" / "scenarios" / "novak2018.toml")
    sc = scale_scenario(base, VEHICLES)
    sc = msgspec.structs.replace(
        sc, time=msgspec.structs.replace(sc.time, startup_timeout_s=180.0, duration_s=0.0)
    )
    path = write_scenario(sc, tmp_path / "soak.toml")
    ids = [v.id for v in sc.vehicles]
    wall0 = time.monotonic()
    with plumeswarm_up(
        path, tmp_path, "--headless", "--vehicles-per-process", str(PER_PROCESS),
        ready_timeout_s=300.0,
    ) as up, open_session(NetworkConfig(connect=[up.endpoint], listen=[])) as session:  # fmt: skip
        keys = Keys(sc.world.name)
        obs = Observer(session, keys)
        deadline = time.monotonic() + 300.0
        drive(session, sc, "flying", deadline)
        pids = up.pids()
        samples: list[tuple[float, dict[str, int]]] = []
        ready_wall = time.monotonic()
        while (now_sim := obs.sim_time_s()) < sim_s:
            assert up.proc.poll() is None, up.console.read_text()[-3000:]
            assert up.pids() == pids, "a process was restarted"
            samples.append((now_sim, {name: rss_of(pid) for name, pid in pids.items()}))
            assert time.monotonic() - ready_wall < 5000, f"sim time only {now_sim:.0f} s"
            time.sleep(SAMPLE_PERIOD_S)
        wall = time.monotonic() - ready_wall
        with obs.lock:
            status = dict(obs.status)
            first, last, seen, gaps = obs.first_tick, obs.last_tick, obs.ticks_seen, obs.tick_gaps
        dropped = obs.physics_dropped()
        obs.close()
    total_wall = time.monotonic() - wall0

    window = WINDOW_FRACTION * sim_s
    early = [s for t, s in samples if window <= t < 2 * window]
    late = [s for t, s in samples if t >= sim_s - window]
    assert early and late, f"too few RSS samples ({len(samples)})"
    growth = {}
    for name in pids:
        a = statistics.median(s[name] for s in early)
        b = statistics.median(s[name] for s in late)
        growth[name] = (a / 2**20, b / 2**20, (b - a) / a)
    rows = "\n".join(
        f"  {n:24s} {a:7.1f} MB -> {b:7.1f} MB ({g:+.1%})" for n, (a, b, g) in growth.items()
    )
    print(
        f"\nsoak: {VEHICLES} vehicles, K={PER_PROCESS}, {sim_s:.0f} s sim in {wall:.0f} s wall "
        f"(RTF {sim_s / wall:.2f}; {total_wall:.0f} s with start and stop); ticks {first}..{last}: "
        f"{seen} seen, {len(gaps)} gaps; physics dropped {dropped}; RSS (median of sim "
        f"{window:.0f}-{2 * window:.0f} s vs last {window:.0f} s):\n{rows}"
    )
    assert not gaps, f"ticks missing at the test's subscriber: {gaps[:10]}"
    assert seen == last - first + 1
    assert dropped == 0, "physics dropped participants"
    for vid in ids:
        st = status[vid]
        assert st.armed and st.mode == FlightMode.MISSION and not st.crashed, (vid, st)
    worst = {n: g for n, (_, _, g) in growth.items() if abs(g) > RSS_TOLERANCE}
    assert not worst, f"RSS not flat within {RSS_TOLERANCE:.0%}: {worst}"
