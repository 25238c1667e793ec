"""64 MiB payloads on the bus under ``plumeswarm up --record``: a rogue peer (whose own
message limit is Zenoh's 1 GiB) puts them on a few of the stack's keys, each followed by a
small malformed payload on the same key. The 64 MiB ones are over ``[network]
max_message_size_bytes`` (32 MiB by default) and under Zenoh's transport limit (4 times it):
each receiving process refuses them before decoding or recording them, with a warning naming
the key, the size and the limit (the physics for the actuators, the autopilots for the tick, the
recorder for all three); the small ones reach their receivers, which log a refusal naming the
key; the stack goes on ticking; the recording holds none of the large ones. The recorder's and
the physics' resident memory grows by less than twice the transport limit: one message in
transit, whose fragments and reassembled bytes Zenoh holds at once, each at most the transport
limit (256 MiB by default; ``python -m plumeswarm.bench.rxmemory`` measures up to 1.6 times a
message's size near the limit). It was 64 MiB while Zenoh's transport limit was the limit
itself (it dropped the 64 MiB payloads unlogged); they now reach the processes to be refused
with a line. Measured (``pytest -q -s``): growth up to 141 MiB in four runs (recorder 69.4 →
217.6 MB, physics 102.6 → 227.5 MB); with Zenoh's 1 GiB limit the recorder grew by 377 MiB.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import msgspec
import psutil
import zenoh

from deploy.launcher import Launcher
from recorder.reader import Recording
from swarmbus.codec import MessageError, decode
from swarmbus.messages import SimTick
from swarmbus.scenario import load_scenario
from swarmbus.session import (
    TRANSPORT_MESSAGE_FACTOR,
    NetworkConfig,
    free_tcp_port,
    open_session,
)
from tests.support.mavclient import write_scenario
from tests.support.procs import keys_for, wait_until
from tests.support.upstack import recording_launch

MIB = 2**20
ROGUE_PAYLOAD = 64 * MIB
WATCHED = ("recorder", "physics")
LIMIT = NetworkConfig().max_message_size_bytes  # the stack's: the scenario sets none
# one message in transit: its fragments and its reassembled bytes, each up to the transport limit
RSS_BOUND = 2 * TRANSPORT_MESSAGE_FACTOR * LIMIT


def _rss(pid: int) -> int:
    """Resident bytes of ``pid`` and its children."""
    proc = psutil.Process(pid)
    return int(sum(p.memory_info().rss for p in [proc, *proc.children(recursive=True)]))


class _PeakRss:
    """The peak resident memory of some processes, sampled every 20 ms on a thread."""

    def __init__(self, pids: dict[str, int]) -> None:
        self.start = {name: _rss(pid) for name, pid in pids.items()}
        self.peak = dict(self.start)
        self._pids = pids
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._done.wait(0.02):
            for name, pid in self._pids.items():
                self.peak[name] = max(self.peak[name], _rss(pid))

    def stop(self) -> None:
        self._done.set()
        self._thread.join(5.0)


def _rogue_puts(rogue: zenoh.Session, targets: list[str]) -> list[zenoh.Publisher]:
    """On each target key, twice: a 64 MiB payload and a 1 000-byte malformed one."""
    block = zenoh.CongestionControl.BLOCK
    pubs = [rogue.declare_publisher(k, congestion_control=block) for k in targets]
    wait_until(
        lambda: all(getattr(p.matching_status, "matching", False) for p in pubs),
        30.0,
        "the stack's subscribers matched the rogue's keys",
    )
    huge = b"\xc1" * ROGUE_PAYLOAD  # 0xc1: never valid MessagePack
    for _ in range(2):
        for pub in pubs:
            pub.put(huge)
            pub.put(b"\xc1" * 1000)
    return pubs


def _assert_refused_with_key_and_size(run: Path, targets: list[str]) -> None:
    """Each receiving process logged the 64 MiB payloads' refusal, naming key, size and limit."""

    def refusal(key: str) -> str:
        return f" of {ROGUE_PAYLOAD} bytes on {key}: over [network] max_message_size_bytes {LIMIT}"

    physics_log = (run / "physics.log").read_text()
    assert f"ignoring actuator batch{refusal(targets[0])}" in physics_log
    autopilot_logs = "".join(p.read_text() for p in run.glob("autopilot-*.log"))
    assert f"ignoring tick{refusal(targets[1])}" in autopilot_logs
    recorder_log = (run / "recorder.log").read_text()
    for key in targets:
        assert f"ignoring a message{refusal(key)}" in recorder_log, key


def test_64_mib_payloads_are_refused_the_stack_goes_on_memory_bounded(tmp_path: Path) -> None:
    path, _, _ = write_scenario(tmp_path / "scenario.toml", 3)
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    opts = recording_launch(path, tmp_path / "run", endpoint)
    keys = keys_for()
    targets = [
        keys.autopilot_actuators("autopilot-uav1"),  # the physics
        keys.tick(),  # the autopilots (and the recorder)
        keys.vehicle_concentration("uav2"),  # the recorder alone
    ]
    lock = threading.Lock()
    ticks: list[int] = []

    def on_tick(sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        try:
            tick = decode(payload, SimTick).tick
        except MessageError:
            return  # the rogue's own garbage on sim/tick
        with lock:
            ticks.append(tick)

    subs: list[zenoh.Subscriber[None]] = []
    launcher = Launcher(load_scenario(path), opts)

    def last_tick() -> int:
        with lock:
            return max(ticks, default=-1)

    def supervised(predicate: Callable[[], bool]) -> Callable[[], bool]:
        def check() -> bool:
            launcher.supervise_once()
            return predicate()

        return check

    rss: _PeakRss | None = None
    try:
        launcher.start(lambda s: subs.append(s.declare_subscriber(keys.tick(), on_tick)))
        wait_until(supervised(lambda: last_tick() >= 300), 120.0, "300 ticks")
        pids = {name: launcher.supervisor.pids()[name] for name in WATCHED}
        rss = _PeakRss(pids)
        rogue_net = NetworkConfig(
            mode="peer", connect=[endpoint], max_message_size_bytes=2**30, shared_memory=False
        )
        with open_session(rogue_net) as rogue:
            pubs = _rogue_puts(rogue, targets)
            at = last_tick()
            wait_until(supervised(lambda: last_tick() >= at + 300), 120.0, "300 more ticks")
            for pub in pubs:
                pub.undeclare()
        rss.stop()
        alive = launcher.supervisor.pids()
        assert {n: alive[n] for n in WATCHED} == pids  # none restarted
    finally:
        if rss is not None:
            rss.stop()
        for sub in subs:
            sub.undeclare()
        launcher.stop()
    assert rss is not None
    growth = {name: rss.peak[name] - rss.start[name] for name in WATCHED}
    print(
        "\nRSS at start / peak while the rogue put 6 × 64 MiB (MB): "
        + ", ".join(f"{n} {rss.start[n] / 1e6:.1f} / {rss.peak[n] / 1e6:.1f}" for n in WATCHED)
    )
    assert LIMIT < ROGUE_PAYLOAD <= TRANSPORT_MESSAGE_FACTOR * LIMIT  # reaches the processes
    assert all(g < RSS_BOUND for g in growth.values()), growth
    run = opts.run_dir
    physics_log = (run / "physics.log").read_text()
    assert f"ignoring actuator batch on {targets[0]}: invalid ActuatorBatch" in physics_log
    autopilot_logs = "".join(p.read_text() for p in run.glob("autopilot-*.log"))
    assert f"ignoring bad tick on {targets[1]}: invalid" in autopilot_logs
    _assert_refused_with_key_and_size(run, targets)
    recording = Recording.open(run / "recording.mcap")
    recorded = [m for m in recording.messages() if m.topic in targets]
    # the small malformed payloads, twice on each key; nothing near the 64 MiB
    garbage = [m.topic for m in recorded if m.data == b"\xc1" * 1000]
    assert sorted(garbage) == sorted(targets * 2)
    assert max(len(m.data) for m in recorded) < MIB
    summary = recording.metadata["plumeswarm.summary"]  # read with the messages
    assert msgspec.json.decode(summary["refused"]) == dict.fromkeys(targets, 2)
