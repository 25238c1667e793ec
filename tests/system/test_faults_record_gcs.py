"""Faults at the edges of ``plumeswarm up --record`` (with its viewer) while three vehicles fly
looping missions: the viewer and the recorder SIGKILLed and restarted (the recorder continues
in a new segment and records the gap there), then a real MAVLink ground station that stops
sending heartbeats: each vehicle performs its own configured data-link-loss failsafe. Recovery
times are printed (-s)."""

from __future__ import annotations

import time
import urllib.request
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import pytest
import zenoh

from deploy.busview import BusView
from deploy.scaling import write_scenario
from gcs_bridge.dialect import mavlink
from gcs_bridge.modes import Px4AutoSub, Px4Main
from plumeswarm.bench.scale import drive
from recorder.reader import Recording, segment_end
from recorder.schema import SegmentGap
from swarmbus.codec import decode
from swarmbus.keys import Keys
from swarmbus.messages import (
    FlightMode,
    NodeHealth,
    SimTick,
    VehicleStatus,
)
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, open_session
from tests.support.mavclient import MavClient
from tests.support.mavclient import write_scenario as write_gcs_scenario
from tests.support.procs import run_cli, wait_until
from tests.support.recording import ticks_not_recorded
from tests.support.upstack import StackOnBus, plumeswarm_up

VEHICLES = ["uav1", "uav2", "uav3"]
# each vehicle's own data-link-loss failsafe (per-vehicle [vehicles.failsafe] sections)
LINK_LOSS = {"uav1": ("hold", 3.0), "uav2": ("land", 4.0), "uav3": ("rtl", 5.0)}
DATALINK_LOST = "ground-control link lost"


@dataclass
class Stack(StackOnBus):
    link_lost: dict[str, VehicleStatus] = field(default_factory=dict)  # first status saying so

    def health(self, name: str) -> NodeHealth | None:
        return self.view.snapshot().health.get(name)

    def sim_time_s(self) -> float:
        clock = self.view.snapshot().clock
        return clock.sim_time_s if clock is not None else 0.0


def scenario_with_failsafes(tmp: Path) -> tuple[Path, int]:
    path, gcs_port, _ = write_gcs_scenario(tmp / "base.toml", len(VEHICLES))
    sc = load_scenario(path)
    vehicles = []
    for v in sc.vehicles:
        action, timeout_s = LINK_LOSS[v.id]
        failsafe = msgspec.structs.replace(
            sc.failsafe, datalink_loss_action=action, datalink_timeout_s=timeout_s
        )
        vehicles.append(msgspec.structs.replace(v, failsafe=failsafe))
    sc = msgspec.structs.replace(sc, vehicles=vehicles)
    return write_scenario(sc, tmp / "scenario.toml"), gcs_port


@pytest.fixture(scope="module")
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stack]:
    tmp = tmp_path_factory.mktemp("edges")
    path, gcs_port = scenario_with_failsafes(tmp)
    sc = load_scenario(path)
    with (
        plumeswarm_up(path, tmp, "--record") as up,
        open_session(NetworkConfig(connect=[up.endpoint], listen=[])) as session,
    ):
        keys = Keys(sc.world.name)
        st = Stack(up, session, keys, BusView(session, keys), gcs_port)

        def on_status(sample: zenoh.Sample) -> None:
            s = decode(sample.payload.to_bytes(), VehicleStatus)
            with st.lock:
                if s.failsafe == DATALINK_LOST and s.vehicle_id not in st.link_lost:
                    st.link_lost[s.vehicle_id] = s

        sub = session.declare_subscriber(keys.all_vehicle_status(), on_status)
        deadline = time.monotonic() + 120.0
        assert [v.id for v in sc.vehicles] == VEHICLES
        drive(session, sc, "flying", deadline)

        def flying() -> bool:
            snap = st.view.snapshot().vehicles
            return all(
                (v := snap.get(vid)) is not None
                and v.status is not None
                and v.status.mode == FlightMode.MISSION
                and v.position is not None
                and v.position[2] > 5.0
                for vid in VEHICLES
            )

        wait_until(flying, 240.0, "every vehicle flying its mission", poll_s=0.2)
        yield st
        sub.undeclare()
        st.view.close()


def _viewer_tick(h: NodeHealth | None, pid: int) -> int | None:
    """The newest tick the viewer process ``pid`` drew, from its health detail."""
    if h is None or h.pid != pid or "plume=3/3" not in h.detail:
        return None
    fields = dict(w.split("=", 1) for w in h.detail.split() if "=" in w)
    tick = fields.get("tick", "-")
    return int(tick) if tick != "-" else None


def _serves_page(h: NodeHealth) -> bool:
    url = h.detail.split()[0].removeprefix("url=")
    with urllib.request.urlopen(url, timeout=10.0) as page:
        return page.status == 200 and b"<html" in page.read().lower()


def test_viewer_killed_serves_its_page_and_scene_again(stack: Stack) -> None:
    pid = stack.up.pids()["viewer"]
    tick0 = wait_until(lambda: _viewer_tick(stack.health("viewer"), pid), 60.0, "viewer drawing")
    health = stack.health("viewer")
    assert health is not None and _serves_page(health)
    new, restart_s, _ = stack.up.kill("viewer")
    t0 = time.monotonic()
    tick1 = wait_until(
        lambda: _viewer_tick(stack.health("viewer"), new), 90.0, "the new viewer drawing ticks"
    )
    health = stack.health("viewer")
    assert health is not None and health.pid == new
    assert _serves_page(health)
    back_s = time.monotonic() - t0 + restart_s
    # the new viewer is fed: the tick it draws moves on
    wait_until(
        lambda: (t := _viewer_tick(stack.health("viewer"), new)) is not None and t > tick1,
        30.0,
        "the new viewer's drawn tick to advance",
    )
    assert tick1 > tick0
    print(f"\nviewer: restarted in {restart_s:.1f} s, page and scene (plume 3/3, ticks) back "
          f"after {back_s:.1f} s")  # fmt: skip


def _gap_and_new_ticks(seg1: Path) -> tuple[SegmentGap, int] | None:
    if not seg1.exists():
        return None
    recording = Recording.open(seg1)
    gaps = recording.gaps()
    ticks = [m for m in recording.messages() if m.topic.endswith("/sim/tick")]
    return (gaps[0], len(ticks)) if gaps and len(ticks) > 50 else None


def test_recorder_killed_continues_in_a_new_segment_with_the_gap(
    stack: Stack, tmp_path: Path
) -> None:
    run = stack.up.run
    seg0, seg1 = run / "recording.mcap", run / "recording.1.mcap"
    wait_until(
        lambda: seg0.exists() and (segment_end(seg0).last_tick or 0) > 100,
        60.0,
        "ticks in the first segment",
        poll_s=1.0,
    )
    _, restart_s, kill_ns = stack.up.kill("recorder")
    t0 = time.monotonic()
    found = wait_until(
        lambda: _gap_and_new_ticks(seg1), 90.0, "the gap and new ticks in recording.1.mcap", 1.0
    )
    back_s = time.monotonic() - t0 + restart_s
    gap, new_ticks = found
    assert isinstance(gap, SegmentGap)
    end = segment_end(seg0)  # the killed segment alone, read to its last complete chunk
    assert end.truncated and end.messages > 0
    assert gap.previous_segment == "recording.mcap" and gap.previous_truncated
    assert gap.previous_messages == end.messages
    assert gap.previous_last_tick == end.last_tick
    assert gap.previous_last_log_time_ns is not None and gap.previous_last_log_time_ns <= kill_ns
    assert gap.first_log_time_ns is not None and gap.first_log_time_ns > kill_ns
    assert gap.first_tick is not None and end.last_tick is not None
    assert gap.first_tick > end.last_tick
    assert gap.ticks_missing == gap.first_tick - end.last_tick - 1
    assert gap.gap_s is not None and gap.gap_s > 0
    # the new segment has messages after the restart: ticks from first_tick on
    rec1 = Recording.open(seg1)
    ticks = [
        m.message().tick
        for m in rec1.messages()
        if m.topic == stack.keys.tick() and isinstance(m.message(), SimTick)
    ]
    assert ticks[0] == gap.first_tick and len(ticks) >= new_ticks
    # "0 missing" measured on the recording itself, not taken from the gap record: every tick
    # from the first recorded to the last is in one of the segments (both read, in order)
    absent = ticks_not_recorded(seg0, stack.keys.tick())
    assert absent == [], f"{len(absent)} ticks not recorded: {absent[:10]}"
    assert gap.ticks_missing == 0
    # report reads the run directory: both segments, and says what was not recorded
    out = tmp_path / "report"
    r = run_cli(["report", str(run), "--out", str(out)], timeout_s=240.0)
    assert r.returncode == 0, r.stderr[-2000:]
    md = (out / "report.md").read_text()
    assert "recording.mcap, recording.1.mcap" in md and "not recorded after recording.mcap" in md
    print(f"\nrecorder: restarted in {restart_s:.1f} s, recording again after {back_s:.1f} s; "
          f"not recorded: {gap.gap_s:.2f} s, {gap.ticks_missing} ticks "
          f"({gap.previous_last_tick} → {gap.first_tick}); killed segment: {end.messages} "
          f"messages readable")  # fmt: skip


PX4_MODE = {
    "hold": (Px4Main.AUTO, Px4AutoSub.LOITER, FlightMode.HOLD),
    "land": (Px4Main.AUTO, Px4AutoSub.LAND, FlightMode.LAND),
    "rtl": (Px4Main.AUTO, Px4AutoSub.RTL, FlightMode.RTL),
}


def _heartbeat_mode(gcs: MavClient, sysid: int, main: int, sub: int) -> bool:
    custom = (main << 16) | (sub << 24)
    return any(
        m.custom_mode == custom and m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        for m in gcs.logged("HEARTBEAT", sysid)
    )


def test_gcs_heartbeats_stop_each_vehicle_runs_its_own_failsafe(stack: Stack) -> None:
    sysid = {vid: i + 1 for i, vid in enumerate(VEHICLES)}
    with MavClient(stack.gcs_port) as gcs:
        for sid in sysid.values():
            gcs.wait_type("HEARTBEAT", sid, timeout_s=60.0)
        gcs.beat = True  # QGC-like: a GCS HEARTBEAT every wall second while pumping
        t_beat = stack.sim_time_s()
        longest = max(t for _, t in LINK_LOSS.values())
        gcs.until(
            "heartbeats to flow for longer than the longest link-loss timeout",
            lambda: stack.sim_time_s() > t_beat + longest + 2.0,
            timeout_s=180.0,
        )
        with stack.lock:
            assert not stack.link_lost, f"failsafe while the GCS was beating: {stack.link_lost}"
        for vid in VEHICLES:  # still flying their missions, on the bus and over MAVLink
            status = stack.view.snapshot().vehicles[vid].status
            assert status is not None and status.mode == FlightMode.MISSION, vid
            assert _heartbeat_mode(gcs, sysid[vid], Px4Main.AUTO, Px4AutoSub.MISSION), vid
        gcs.beat = False
        t_stop = stack.sim_time_s()
        wall0 = time.monotonic()
        gcs.log.clear()

        def all_failsafes() -> bool:
            with stack.lock:
                return len(stack.link_lost) == len(VEHICLES) and all(
                    _heartbeat_mode(gcs, sysid[v], *PX4_MODE[LINK_LOSS[v][0]][:2]) for v in VEHICLES
                )

        gcs.until("every vehicle's link-loss failsafe, on the bus and in MAVLink", all_failsafes,
                  timeout_s=180.0)  # fmt: skip
        wall = time.monotonic() - wall0
    lines = []
    for vid in VEHICLES:
        action, timeout_s = LINK_LOSS[vid]
        lost = stack.link_lost[vid]
        assert lost.mode == PX4_MODE[action][2] and lost.armed, (vid, lost)
        after = lost.sim_time_s - t_stop
        # the gateway forwards the GCS's heartbeat once per sim second: the last one the
        # vehicle got is at most ~1 s of sim time before the test stopped beating
        assert after >= timeout_s - 1.5, (vid, after)
        lines.append(f"{vid} {action} (timeout {timeout_s:.0f} s) at +{after:.1f} s sim")
    print(f"\nGCS link loss: {'; '.join(lines)} after the last GCS heartbeat; all seen over "
          f"MAVLink within {wall:.1f} s wall")  # fmt: skip
