"""The physics process's test rig: a two-vehicle scenario, scripted participants in their own
processes, and a watch of every ``sim/tick`` and ``sim/clock`` on the test's session (world
``physics-test``). The ``rig`` fixture (tests/conftest.py) hands a test its node processes and
watch."""

from __future__ import annotations

import hashlib
import json
import subprocess
import threading
from pathlib import Path

import zenoh

from swarmbus.codec import decode
from swarmbus.keys import Keys
from swarmbus.messages import Clock, SimTick
from swarmbus.session import Presence
from tests.support.procs import NodeProcs, wait_until

WORLD = "physics-test"
KEYS = Keys(WORLD)


Spawn = tuple[float, float, float]


def vehicles_toml(*vehicles: tuple[str, str, Spawn]) -> str:
    """The ``[[vehicles]]`` tables of a scenario: each vehicle's id, type and spawn (ENU m)."""
    return "".join(
        f'[[vehicles]]\nid = "{vid}"\ntype = "{vtype}"\nspawn_enu_m = [{x}, {y}, {z}]\n'
        for vid, vtype, (x, y, z) in vehicles
    )


def two_vehicle_scenario(
    tmp_path: Path,
    timeout_s: float = 1.0,
    startup_s: float = 60.0,
    name: str = "sc.toml",
    extra_time: str = "",
) -> Path:
    """Vehicles a (iris) and b (typhoon_h480) in world ``physics-test``; returns the path."""
    path = tmp_path / name
    path.write_text(
        f"""
[world]
name = "{WORLD}"
seed = 7
[time]
physics_hz = 240
control_hz = 120
participant_timeout_s = {timeout_s}
startup_timeout_s = {startup_s}
{extra_time}
{vehicles_toml(("a", "iris", (0.0, 0.0, 0.0)), ("b", "typhoon_h480", (5.0, 0.0, 0.0)))}"""
    )
    return path


def start_script(
    procs: NodeProcs, scenario: Path, *args: str, label: str
) -> subprocess.Popen[bytes]:
    """A scripted participant in its own process group, stopped with the node processes."""
    assert procs.log_dir is not None
    return procs.start_module(
        "tests.support.scripted_participant",
        *("--connect", procs.net.endpoint, "--scenario", str(scenario), *args),
        label=label,
    )


def fly_a_and_b(procs: NodeProcs, scenario: Path, *a_args: str) -> subprocess.Popen[bytes]:
    """A physics and two scripted participants at 0.2 throttle: a (with ``a_args``) and b;
    a's process."""
    procs.start("physics", "--scenario", str(scenario), name="physics")
    a = start_script(
        procs, scenario, "--vehicle", "a", "--throttle", "0.2", *a_args, label="script-a"
    )
    start_script(procs, scenario, "--vehicle", "b", "--throttle", "0.2", label="script-b")
    return a


class Watch:
    """Every ``sim/tick`` and ``sim/clock`` seen by the test's own (router) session."""

    def __init__(self, session: zenoh.Session) -> None:
        self.lock = threading.Lock()
        self.raw: dict[int, bytes] = {}
        self.motors: dict[int, dict[str, bool]] = {}
        self.last_tick = -1
        self.clock: Clock | None = None
        self.session = session
        self._subs = [
            session.declare_subscriber(KEYS.tick(), self._on_tick),
            session.declare_subscriber(KEYS.clock(), self._on_clock),
        ]

    def _on_tick(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        msg = decode(data, SimTick)
        with self.lock:
            self.raw[msg.tick] = data
            self.motors[msg.tick] = {s.vehicle_id: s.motors_enabled for s in msg.states}
            self.last_tick = max(self.last_tick, msg.tick)

    def _on_clock(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.clock = decode(sample.payload.to_bytes(), Clock)

    def first_tick_after(self, tick: int, vid: str, enabled: bool) -> int:
        """The first tick after ``tick`` with ``vid``'s motors ``enabled``; 0 if none yet."""
        with self.lock:
            hits = [k for k, m in self.motors.items() if k > tick and m.get(vid) is enabled]
        return min(hits) if hits else 0

    def forget(self) -> None:
        """Drop the ticks seen so far (the next run starts again from tick 0)."""
        with self.lock:
            self.raw.clear()
            self.last_tick = -1

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def report(path: Path) -> dict[str, object]:
    data: dict[str, object] = json.loads(path.read_text())
    return data


def exit_code(proc: subprocess.Popen[bytes], what: str, timeout_s: float = 60.0) -> int:
    try:
        return proc.wait(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise AssertionError(f"{what} did not exit within {timeout_s} s") from None


def ticks_digest(watch: Watch, ticks: int) -> tuple[str, SimTick]:
    """The SHA-256 of the encoded ticks 0..``ticks`` seen, and the last one (waits for them)."""
    wait_until(lambda: len(watch.raw) == ticks + 1, 10.0, f"ticks 0..{ticks} at the subscriber")
    digest = hashlib.sha256()
    for k in range(ticks + 1):
        digest.update(watch.raw[k])
    return digest.hexdigest(), decode(watch.raw[ticks], SimTick)


def fly_scripted(
    procs: NodeProcs,
    watch: Watch,
    sc: Path,
    ticks: int,
    label: str,
    *script_args: str,
    physics_args: tuple[str, ...] = (),
) -> None:
    """A physics (with ``physics_args``) to tick ``ticks`` and one scripted participant flying a
    and b up to 3 m, both exited cleanly; ``watch`` starts again from tick 0."""
    watch.forget()
    physics = procs.start(
        "physics", "--scenario", str(sc), "--set", f"max_ticks={ticks}", *physics_args,
        name=f"physics-{label}",
    )  # fmt: skip
    script = start_script(
        procs, sc, "--vehicle", "a", "--vehicle", "b", "--altitude", "3.0",
        "--max-tick", str(ticks), *script_args, label=label,
    )  # fmt: skip
    assert exit_code(physics, "physics") == 0
    assert exit_code(script, "participant") == 0


def climbed_digest(watch: Watch, ticks: int, vehicle_ids: tuple[str, ...] | None = None) -> str:
    """:func:`ticks_digest` of a flight whose vehicles (``vehicle_ids``, default all) all
    climbed above 1 m by tick ``ticks``."""
    digest, last = ticks_digest(watch, ticks)
    flown = [s for s in last.states if vehicle_ids is None or s.vehicle_id in vehicle_ids]
    assert all(s.position_enu_m[2] > 1.0 for s in flown), "vehicles should have climbed"
    return digest


def stream_hash(
    procs: NodeProcs, watch: Watch, sc: Path, ticks: int, label: str, *script_args: str
) -> str:
    """The digest of :func:`fly_scripted`'s ticks 0..``ticks``."""
    fly_scripted(procs, watch, sc, ticks, label, *script_args)
    return climbed_digest(watch, ticks)


def wait_for_plume(watch: Watch) -> None:
    """Until a plume service's token is up on the bus."""
    presence = Presence(watch.session, KEYS)
    assert presence.wait_for(lambda alive: "plume" in alive, 60.0), sorted(presence.alive)
    presence.close()
