"""Router outage benchmark: N vehicles, every node a client of the router, the router gone for
S seconds; how long the catch-up takes and how much memory the physics holds.

Run with ``python -m plumeswarm.bench.outage [--vehicles 128] [--outage-s 60]
[--vehicles-per-process 32] [--out DIR]``. The bench owns the router (``plumeswarm node router`` on
a free loopback port; killed with SIGKILL, started again after the outage) and starts physics,
plume and the autopilots with the launcher (lockstep, the default scenario scaled by
``deploy.scaling``, vehicles on the ground). Its own client session subscribes to every
``vehicle/<id>/state``, so the physics puts the states and, when the subscription matches
again after the outage, puts its kept ticks' states
again (``swarmbus.catchup``). It kills the router, waits, starts a new one on the same
endpoint, and measures:

- the physics' resident memory (with children) before the outage and its peak until the
  catch-up is done, sampled every 0.1 s;
- the ticks the physics went on without its participants (after ``restart_grace_s``);
- from the router's return: the first tick seen again, the catch-up's end (the physics' log
  line ``... re-sent the states of ticks a..b (N puts in T s)``), the re-sent states the bench
  received, and the longest wait between two ticks it saw during the catch-up (a stalled tick
  loop shows there).

Prints a table and writes ``outage.json`` in ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from itertools import pairwise
from pathlib import Path
from typing import Any

import msgspec
import psutil
import zenoh

from deploy.launcher import Launcher, LaunchOptions
from deploy.scaling import local_stack_scenario, scale_scenario, write_scenario
from swarmbus.codec import MessageError, decode
from swarmbus.keys import Keys
from swarmbus.messages import Clock
from swarmbus.scenario import DEFAULT_SCENARIO, load_scenario
from swarmbus.session import NetworkConfig, open_session
from swarmbus.views import StateHead

CATCH_UP = re.compile(
    r"re-sent the states of ticks (?P<first>\d+)\.\.(?P<last>\d+) "
    r"\((?P<puts>\d+) puts in (?P<s>[0-9.]+) s\)"
)


class _Observer:
    """The bench's client session: every state (counted after the return) and the clock."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.lock = threading.Lock()
        self.tick = -1
        self.tick_times: list[tuple[float, int]] = []  # (wall, tick) of each clock seen
        self.states_after = 0
        self.counting = False
        self._subs = [
            session.declare_subscriber(keys.all_vehicle_states(), self._on_state),
            session.declare_subscriber(keys.clock(), self._on_clock),
        ]

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            decode(sample.payload.to_bytes(), StateHead)
        except MessageError:
            return
        with self.lock:
            self.states_after += self.counting

    def _on_clock(self, sample: zenoh.Sample) -> None:
        try:
            clock = decode(sample.payload.to_bytes(), Clock)
        except MessageError:
            return
        with self.lock:
            self.tick = max(self.tick, clock.tick)
            self.tick_times.append((time.monotonic(), clock.tick))

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def _rss(pid: int) -> int:
    proc = psutil.Process(pid)
    return int(sum(p.memory_info().rss for p in [proc, *proc.children(recursive=True)]))


def _wait(pred: Any, timeout_s: float, what: str, launcher: Launcher) -> None:
    deadline = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > deadline:
            raise RuntimeError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        launcher.supervise_once()
        time.sleep(0.1)


def _router(path: Path, endpoint: str, log: Path) -> subprocess.Popen[bytes]:
    """``plumeswarm node router`` on ``endpoint`` (its token tells the nodes of the outage)."""
    argv = [sys.executable, "-m", "plumeswarm", "-v", "node", "router", "--scenario", str(path)]
    with open(log, "ab") as out:
        proc = subprocess.Popen(
            [*argv, "--listen", endpoint], stdout=out, stderr=subprocess.STDOUT,
            start_new_session=True,
        )  # fmt: skip
    return proc


def _kill(proc: subprocess.Popen[bytes]) -> None:
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait(10.0)


def run(vehicles: int, outage_s: float, per_process: int, out: Path) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    sc = scale_scenario(load_scenario(DEFAULT_SCENARIO), vehicles)
    sc, _ = local_stack_scenario(sc, out, "lockstep", startup_timeout_s=300.0)
    endpoint = sc.network.connect[0]
    sc = msgspec.structs.replace(
        sc, network=msgspec.structs.replace(sc.network, mode="client", listen=[])
    )
    path = write_scenario(sc, out / "scenario.toml")
    client = NetworkConfig(mode="client", connect=[endpoint], listen=[])
    keys = Keys(sc.world.name)
    opts = LaunchOptions(
        node_command=(sys.executable, "-m", "plumeswarm"),
        scenario_path=path,
        headless=True,
        run_dir=out / "run",
        connect=(endpoint,),
        roles=("plume", "physics", "autopilot"),
        router=False,
        vehicles_per_process=per_process,
    )
    router_log = out / "router.log"
    router = _router(path, endpoint, router_log)
    launcher = Launcher(sc, opts)
    row: dict[str, Any] = {"vehicles": vehicles, "outage_s": outage_s, "per_process": per_process}
    try:
        launcher.start()
        with open_session(client) as session:
            obs = _Observer(session, keys)
            _wait(lambda: obs.tick >= 200, 300.0, "200 ticks", launcher)
            physics = launcher.supervisor.pids()["physics"]
            row["physics_rss_before_mb"] = _rss(physics) / 1e6
            peak = [_rss(physics)]
            done = threading.Event()

            def sample() -> None:
                while not done.wait(0.1):
                    peak[0] = max(peak[0], _rss(physics))

            sampler = threading.Thread(target=sample, daemon=True)
            sampler.start()
            tick_before = obs.tick
            _kill(router)
            time.sleep(outage_s)
            router = _router(path, endpoint, router_log)
            back = time.monotonic()
            with obs.lock:
                obs.counting = True
            log_path = opts.run_dir / "physics.log"
            _wait(
                lambda: CATCH_UP.search(log_path.read_text()) is not None,
                600.0,
                "the physics' catch-up",
                launcher,
            )
            caught_up = time.monotonic() - back
            time.sleep(2.0)
            done.set()
            sampler.join(2.0)
            m = CATCH_UP.search(log_path.read_text())
            assert m is not None
            with obs.lock:
                after = [(t - back, k) for t, k in obs.tick_times if t >= back]
                states_after = obs.states_after
            row |= {
                "physics_rss_peak_mb": peak[0] / 1e6,
                "tick_at_outage": tick_before,
                "kept_ticks": int(m["last"]) - int(m["first"]) + 1,
                "catch_up_puts": int(m["puts"]),
                "catch_up_worker_s": float(m["s"]),
                "catch_up_logged_after_return_s": caught_up,
                "first_clock_after_return_s": after[0][0] if after else None,
                "longest_clock_gap_after_s": max(
                    (b[0] - a[0] for a, b in pairwise(after)), default=None
                ),
                "states_received_after_return": states_after,
            }
            obs.close()
    finally:
        launcher.stop()
        _kill(router)
    return row


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--vehicles", type=int, default=128)
    p.add_argument("--outage-s", type=float, default=60.0)
    p.add_argument("--vehicles-per-process", type=int, default=32)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args()
    out = args.out or Path(tempfile.mkdtemp(prefix="bench-outage-"))
    row = run(args.vehicles, args.outage_s, args.vehicles_per_process, out)
    print("| measure | value |\n|---|---:|")
    for k, v in row.items():
        print(f"| {k} | {v:.2f} |" if isinstance(v, float) else f"| {k} | {v} |")
    (out / "outage.json").write_text(json.dumps(row, indent=2))
    print(f"wrote {out / 'outage.json'}")


if __name__ == "__main__":
    main()
