"""Hosts whose clocks disagree: the simulation does not depend on them (docs/reliability.md,
"Clocks of the hosts").

Two lockstep runs of the same flight (router, physics, recorder on the machine's clock; the
plume service, two autopilots flying their missions from tick START_TICK on, and a scripted
third vehicle parked on the ground that holds START_TICK until the missions are started):
one with every clock the machine's, one with autopilot-uav1's wall clock 5 s ahead,
autopilot-uav2's 5 s behind and the plume service's 0.4 s ahead (libfaketime preloaded into
those processes: their ``time.time()`` and Zenoh's timestamps move, their monotonic clocks
not). Every vehicle's state of every tick and every plume reading are the same bytes in both
runs, and no process logs a timeout, a drop or a refusal. The recorder names the two
autopilots whose clocks are beyond Zenoh's 0.5 s bound, and only them: uav1's samples
re-stamped on arrival (its clock ahead), uav2's publisher 5 s behind.
"""

from __future__ import annotations

import re
import threading
from dataclasses import dataclass, field
from pathlib import Path

import pytest
import zenoh

from plumeswarm.experiments.chaos import keep_state
from recorder.reader import Recording
from recorder.schema import EVENTS_TOPIC
from swarmbus.codec import decode
from swarmbus.messages import (
    Arm,
    CommandReply,
    ConcentrationReading,
    MissionStart,
    VehicleState,
)
from swarmbus.reqrep import request
from swarmbus.session import Presence
from tests.support.mavclient import write_scenario
from tests.support.procs import NodeProcs, keys_for, wait_until, zenoh_network
from tests.support.skewed_clock import faketime_library, skewed_clock_env

pytestmark = pytest.mark.skipif(
    faketime_library() is None, reason="libfaketime is not installed (pip install libfaketime)"
)

FLYING = ("uav1", "uav2")
GATE = "uav3"  # parked, scripted: holds START_TICK until the missions are started
START_TICK = 60
END_TICK = START_TICK + 4 * 120  # 4 s of sim time into the missions (control at 120 Hz)
SKEWED = {"autopilot-uav1": 5.0, "autopilot-uav2": -5.0, "plume": 0.4}
# what a run must never log: a participant dropped or held for, a refusal, a lost state
TROUBLE = re.compile(
    r"dropped|refus|holding the clock|no answer|state lost|failsafe|Traceback", re.IGNORECASE
)


@dataclass
class Flight:
    logs: Path
    recording: Path
    lock: threading.Lock = field(default_factory=threading.Lock)
    states: dict[str, dict[int, bytes]] = field(default_factory=dict)
    conflicts: list[tuple[str, int]] = field(default_factory=list)
    readings: dict[str, dict[float, bytes]] = field(default_factory=dict)

    def on_state(self, sample: zenoh.Sample) -> None:
        with self.lock:
            keep_state(self.states, self.conflicts, sample.payload.to_bytes())

    def on_reading(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        r = decode(payload, ConcentrationReading)
        with self.lock:
            self.readings.setdefault(r.vehicle_id, {}).setdefault(r.sim_time_s, payload)

    def last_tick(self, vid: str) -> int:
        with self.lock:
            ticks = self.states.get(vid)
            return max(ticks) if ticks else -1

    def last_reading_s(self, vid: str) -> float:
        with self.lock:
            times = self.readings.get(vid)
            return max(times) if times else -1.0

    def log(self, label: str) -> str:
        return (self.logs / f"{label}.log").read_text(errors="replace")


def fly(tmp: Path, skews: dict[str, float], mode: str) -> Flight:
    """The flight up to END_TICK, each process in ``skews`` with its clock that far off, every
    node in network ``mode``."""
    tmp.mkdir()
    path, _, _ = write_scenario(tmp / "scenario.toml", len(FLYING) + 1)
    path.write_text(path.read_text() + f'\n[network]\nmode = "{mode}"\n')
    f = Flight(tmp, tmp / "recording.mcap")
    keys = keys_for()
    release = tmp / "release"

    def env(label: str) -> dict[str, str] | None:
        return skewed_clock_env(skews[label]) if label in skews else None

    with zenoh_network() as (net, session), NodeProcs(net, path, tmp) as procs:
        subs = [
            session.declare_subscriber(keys.all_vehicle_states(), f.on_state),
            session.declare_subscriber(keys.all_vehicle_concentration(), f.on_reading),
        ]
        procs.start("plume", name="plume", env=env("plume"))
        procs.start("recorder", "--set", f"out={f.recording}", name="recorder")
        presence = Presence(session, keys)
        up = presence.wait_for(lambda alive: {"plume", "recorder"} <= set(alive), 60.0)
        presence.close()
        assert up, "plume and recorder on the bus"
        procs.start("physics", name="physics")
        for vid in FLYING:
            label = f"autopilot-{vid}"
            procs.start("autopilot", "--vehicle", vid, name=label, env=env(label))
        procs.start_module(
            "tests.support.scripted_participant", *net.cli_args()[:2], "--scenario", str(path),
            "--vehicle", GATE, "--throttle", "0", "--delay-tick", str(START_TICK),
            "--delay-s", "120", "--release-file", str(release), label="gate",
        )  # fmt: skip
        wait_until(
            lambda: all(f.last_tick(v) >= START_TICK for v in (*FLYING, GATE)),
            120.0,
            f"tick {START_TICK}",
        )
        for vid in FLYING:
            for cmd in (Arm(), MissionStart(start_index=0)):
                reply = request(session, keys.vehicle_cmd(vid), cmd, CommandReply, 30.0)
                assert reply.accepted, (vid, cmd, reply.reason)
        assert all(f.last_tick(v) == START_TICK for v in FLYING), "the gate did not hold"
        release.touch()
        # a sensor tick's readings go out with a later tick (the one carrying the plume's
        # answer): wait for them too
        wait_until(
            lambda: (
                all(f.last_tick(v) >= END_TICK for v in (*FLYING, GATE))
                and all(f.last_reading_s(v) >= END_TICK / 120.0 for v in FLYING)
            ),
            120.0,
            f"tick {END_TICK} and its readings",
        )
        dead = [label for label, p in procs.procs if p.poll() is not None]
        assert not dead, f"processes died: {dead}"
        for sub in subs:
            sub.undeclare()
    return f


# peer: every node links to every other (the default); client: everything through the router,
# which then re-stamps the samples of a clock too far ahead
@pytest.mark.parametrize("mode", ["peer", "client"])
def test_a_host_clock_seconds_off_changes_nothing_and_the_recorder_names_it(
    tmp_path: Path, mode: str
) -> None:
    base = fly(tmp_path / "same-clocks", {}, mode)
    skewed = fly(tmp_path / "skewed-clocks", SKEWED, mode)

    for run in (base, skewed):
        assert not run.conflicts, run.conflicts[:5]
        for label in ("physics", "plume", "autopilot-uav1", "autopilot-uav2", "recorder"):
            trouble = [ln for ln in run.log(label).splitlines() if TROUBLE.search(ln)]
            assert not trouble, (run.logs.name, label, trouble[:5])
    # the same bytes, tick by tick and reading by reading
    for vid in (*FLYING, GATE):
        got, want = skewed.states[vid], base.states[vid]
        missing = [t for t in range(END_TICK + 1) if t not in got or t not in want]
        assert not missing, (vid, missing[:5])
        differ = [t for t in range(END_TICK + 1) if got[t] != want[t]]
        assert not differ, f"{vid}: {len(differ)} ticks differ with the skewed clocks"
    # ... the vehicles flew (climbed) meanwhile, so the comparison covers control, not rest
    end_z = decode(base.states["uav1"][END_TICK], VehicleState).position_enu_m[2]
    assert end_z > 2.0, end_z
    for vid in FLYING:
        got_r, want_r = skewed.readings[vid], base.readings[vid]
        times = [t for t in sorted(want_r) if t <= END_TICK / 120.0]
        assert len(times) > 40, (vid, len(times))  # 10 Hz sensor
        unheard = [t for t in times if t not in got_r]
        assert not unheard, f"{vid}: readings of {unheard[:5]} s not received"
        changed = [t for t in times if got_r[t] != want_r[t]]
        assert not changed, f"{vid}: the readings of {changed[:5]} s differ"

    # the recorder names the two clocks beyond the bound, and nothing else
    assert "CLOCK SKEW" not in base.log("recorder")
    warnings = [ln for ln in skewed.log("recorder").splitlines() if "CLOCK SKEW" in ln]
    stamper = "this host's" if mode == "peer" else "the router "
    restamped = [w for w in warnings if "/vehicle/uav1/" in w and "re-stamped" in w]
    assert restamped and stamper in restamped[0], warnings
    behind = [w for w in warnings if "uav2" in w and "behind" in w]
    assert behind, warnings
    seconds = re.search(r"is (\d+\.\d+) s behind", behind[0])
    assert seconds is not None and 4.5 < float(seconds.group(1)) < 5.5, behind[0]
    assert not [w for w in warnings if "uav1" not in w and "uav2" not in w], warnings
    # ... and the recording keeps each publisher's time within the bound (the plume's, 0.4 s
    # ahead, and so every clock it pulled along: a hybrid logical clock never runs behind a
    # time it received), the receiver's beyond it (uav1's, re-stamped), the publisher's behind
    # (uav2's, 5 s)
    offsets = publish_offsets(skewed.recording)
    assert 4.5 < -offsets["vehicle/uav2/status"] < 5.5, offsets
    assert abs(offsets["vehicle/uav1/status"]) < 0.5, offsets
    assert 0.2 < offsets["field/sample"] < 0.5, offsets
    events = [r for r in Recording.open(skewed.recording).messages() if r.topic == EVENTS_TOPIC]
    assert any(b'"clock"' in r.data for r in events), [r.data for r in events]


def publish_offsets(path: Path) -> dict[str, float]:
    """Per key: the largest publish − log time of its recorded messages (s)."""
    out: dict[str, float] = {}
    for rec in Recording.open(path).messages():
        key = keys_for().relative(rec.topic)
        offset = (rec.publish_time_ns - rec.log_time_ns) / 1e9
        out[key] = max(out.get(key, -1e9), offset)
    return out
