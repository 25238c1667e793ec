"""Autopilot benchmarks: control-step cost per vehicle and the lockstep real-time factor.

Run with ``python -m plumeswarm.bench.agents [--counts 1,3,8,16,32,64] [--seconds 5] [--driver
physics]``.

1. In-process cost of one control tick per vehicle (estimate → modes → cascaded control →
   mixer), and of the node's whole per-tick path (decode the SimTick, step, encode the
   one-vehicle ActuatorBatch).
2. Lockstep with N autopilot processes (one per vehicle) hovering at 5 m, plus the plume service
   (the physics queries it on every sensor tick) and the physics process (``--driver physics``)
   or, when the physics role is not available, a minimal lockstep stand-in (``--driver stub``:
   hovering states published in one SimTick, answers awaited; no dynamics, no plume query, so
   the readings are unavailable). Prints ticks/s, the
   real-time factor at 120 Hz control and the machine's CPU share.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import suppress
from pathlib import Path

import psutil

from agents.autopilot import Autopilot
from swarmbus.codec import decode, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    Arm,
    Clock,
    SimTick,
    SpeedMode,
    Takeoff,
    VehicleState,
)
from swarmbus.scenario import load_scenario
from swarmbus.session import NetworkConfig, free_tcp_port, open_session

REPO = Path(__file__).resolve().parent.parent
WORLD = "bench"
HOVER_M = 5.0


def hover_state(vehicle_id: str, tick: int, z: float = HOVER_M) -> VehicleState:
    return VehicleState(
        vehicle_id=vehicle_id,
        tick=tick,
        sim_time_s=tick / 120.0,
        position_enu_m=(0.01, -0.02, z),
        velocity_enu_m_s=(0.01, 0.0, -0.01),
        attitude_xyzw=(0.001, -0.002, 0.0, 1.0),
        body_rates_rad_s=(0.01, -0.01, 0.0),
        lat_deg=47.4,
        lon_deg=8.5,
        alt_m=493.0,
        on_ground=z <= 0.06,
    )


def control_cost(vehicle_type: str, n: int = 20000) -> tuple[float, float]:
    """(µs per Autopilot.step, µs per node tick path) for one hovering vehicle of 3."""
    sc = load_scenario()
    import msgspec

    v = msgspec.structs.replace(sc.vehicles[0], type=vehicle_type, mission=[])
    sc = msgspec.structs.replace(sc, vehicles=[v, *sc.vehicles[1:]])
    ap = Autopilot(sc, v.id)
    ap.step(hover_state(v.id, 0, 0.06))
    assert ap.handle(Arm()).accepted and ap.handle(Takeoff(altitude_m=HOVER_M)).accepted
    state = hover_state(v.id, 1)
    ap.step(state)
    t0 = time.perf_counter()
    for _ in range(n):
        ap.step(state)
    step_us = (time.perf_counter() - t0) / n * 1e6
    tick = encode(
        SimTick(
            tick=1,
            sim_time_s=1 / 120,
            control_dt_s=1 / 120,
            states=[hover_state(x.id, 1) for x in sc.vehicles],
        )
    )
    t0 = time.perf_counter()
    for _ in range(n):
        msg = decode(tick, SimTick)
        own = next(s for s in msg.states if s.vehicle_id == v.id)
        peers = [s for s in msg.states if s.vehicle_id != v.id]
        u = ap.step(own, peers)
        cmd = ActuatorCommand(vehicle_id=v.id, tick=msg.tick, rotor_commands=u)
        encode(ActuatorBatch(tick=msg.tick, commands=[cmd]))
    path_us = (time.perf_counter() - t0) / n * 1e6
    return step_us, path_us


def scenario_text(count: int) -> str:
    side = max(1, int(count**0.5 + 0.999))
    lines = [
        f'[world]\nname = "{WORLD}"\nseed = 1\n',
        '[time]\nphysics_hz = 240\ncontrol_hz = 120\nmode = "lockstep"\n'
        "participant_timeout_s = 10.0\nstartup_timeout_s = 600.0\n",
        '[plume]\npreset = "novak2018"\n',
        '[sensor]\npreset = "novak2018"\n',
    ]
    for i in range(count):
        x, y = 20.0 + 3.0 * (i % side), -12.0 + 3.0 * (i // side)
        lines.append(
            f'[[vehicles]]\nid = "v{i:02d}"\ntype = "iris"\nspawn_enu_m = [{x}, {y}, 0.0]\n'
        )
    return "\n".join(lines)


class Procs:
    def __init__(self, endpoint: str, scenario: Path) -> None:
        self.endpoint = endpoint
        self.scenario = scenario
        self.procs: list[subprocess.Popen[bytes]] = []

    def start(self, role: str, *args: str) -> None:
        cmd = [sys.executable, "-m", "plumeswarm", "node", role, "--scenario", str(self.scenario)]
        cmd += ["--connect", self.endpoint, "--listen", "tcp/127.0.0.1:0", *args]
        env = dict(os.environ, PYTHONPATH=str(REPO))
        self.procs.append(
            subprocess.Popen(
                cmd,
                cwd=REPO,
                env=env,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,
            )
        )

    def cpu_percent(self, interval_s: float) -> float:
        ps = [psutil.Process(p.pid) for p in self.procs if p.poll() is None]
        for p in ps:
            p.cpu_percent(None)
        time.sleep(interval_s)
        total = 0.0
        for p in ps:
            with suppress(psutil.NoSuchProcess):
                total += p.cpu_percent(None)
        return total / (psutil.cpu_count() or 1)

    def stop(self) -> None:
        for p in self.procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        deadline = time.monotonic() + 20
        for p in self.procs:
            try:
                p.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(timeout=5)


class StubPhysics:
    """Lockstep barrier without dynamics: hovering states out, one answer per vehicle back."""

    def __init__(self, session: object, keys: Keys, ids: list[str]) -> None:
        import zenoh

        assert isinstance(session, zenoh.Session)
        self.ids = ids
        self.tick = 0
        self.z = 0.06  # on the ground until the bench has armed and launched everyone
        self.cond = threading.Condition()
        self.answered: dict[str, int] = {}
        self.pub = session.declare_publisher(keys.tick())
        self.clock = session.declare_publisher(keys.clock())
        self.subs = [
            session.declare_subscriber(keys.all_autopilot_actuators(), self._on),
        ]
        self.stop_event = threading.Event()
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _on(self, sample: object) -> None:
        data = sample.payload.to_bytes()  # type: ignore[attr-defined]
        msg = decode(data, ActuatorBatch)
        with self.cond:
            for cmd in msg.commands:
                self.answered[cmd.vehicle_id] = cmd.tick
            self.cond.notify_all()

    def _run(self) -> None:
        last_clock = time.monotonic()
        while not self.stop_event.is_set():
            k = self.tick
            z = self.z
            msg = encode(
                SimTick(
                    tick=k,
                    sim_time_s=k / 120,
                    control_dt_s=1 / 120,
                    states=[hover_state(v, k, z) for v in self.ids],
                )
            )
            self.pub.put(msg)
            republish = time.monotonic() + 0.1
            with self.cond:
                while not all(self.answered.get(v) == k for v in self.ids):
                    if self.stop_event.is_set():
                        return
                    if time.monotonic() > republish:  # start-up handshake
                        self.pub.put(msg)
                        republish = time.monotonic() + 0.1
                    self.cond.wait(0.1)
            self.tick += 1
            now = time.monotonic()
            if now - last_clock > 0.1:
                last_clock = now
                self.clock.put(
                    encode(
                        Clock(
                            tick=self.tick,
                            sim_time_s=self.tick / 120,
                            mode=SpeedMode.LOCKSTEP,
                            speed_factor=1.0,
                            real_time_factor=0.0,
                        )
                    )
                )

    def start(self) -> None:
        self.thread.start()

    def stop(self) -> None:
        self.stop_event.set()
        self.thread.join(timeout=5)


def lockstep_run(
    count: int, seconds: float, driver: str, plume: bool = True, per_process: int = 1
) -> tuple[float, float, float]:
    """(ticks/s, real-time factor, machine CPU %) with ``count`` autopilot processes."""
    from agents import Swarm

    port = free_tcp_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    router_net = NetworkConfig(mode="router", connect=[], listen=[endpoint])
    with tempfile.TemporaryDirectory() as tmp, open_session(router_net) as router:
        path = Path(tmp) / "bench.toml"
        path.write_text(scenario_text(count))
        ids = [f"v{i:02d}" for i in range(count)]
        procs = Procs(endpoint, path)
        keys = Keys(WORLD)
        clocks: list[tuple[float, int, float]] = []
        clock_sub = router.declare_subscriber(
            keys.clock(),
            lambda s: clocks.append((time.monotonic(), *_tick_time(s.payload.to_bytes()))),
        )
        stub = StubPhysics(router, keys, ids) if driver == "stub" else None
        try:
            if plume:
                procs.start("plume")
            for first in range(0, count, per_process):
                group = ids[first : first + per_process]
                args = [a for vid in group for a in ("--vehicle", vid)]
                if len(group) > 1:  # the derived name would outgrow 64 characters
                    args += ["--name", f"autopilots-{first // per_process}"]
                procs.start("autopilot", *args)
            if stub is not None:
                stub.start()
            else:
                procs.start("physics")
            with Swarm(router, keys, command_timeout_s=120.0, own_session=False) as sw:
                sw.wait_until(
                    lambda: all(sw.status(v) is not None for v in ids), 300, "all autopilots"
                )
                sw.wait_until(lambda: len(clocks) > 2, 300, "the lockstep running")
                if stub is not None:
                    sw.wait_until(lambda: stub.tick > 5, 60, "ticks")
                else:
                    sw.wait_until(
                        lambda: all(sw.state(v) is not None for v in ids), 120, "all states"
                    )

                def launch(vid: str) -> None:
                    sw.command(vid).arm()
                    sw.command(vid).takeoff(HOVER_M)

                with ThreadPoolExecutor(max_workers=16) as pool:  # 64 vehicles under load
                    list(pool.map(launch, ids))
                if stub is None:
                    sw.wait_until(
                        lambda: all(sw.status(v).mode == "hold" for v in ids), 600, "all hovering"
                    )
                else:
                    stub.z = HOVER_M
                    first = stub.tick
                    sw.wait_until(lambda: stub.tick > first + 120, 120, "stub airborne")
            start = clocks[-1]
            cpu = procs.cpu_percent(seconds)
            end = clocks[-1]
        finally:
            if stub is not None:
                stub.stop()
            clock_sub.undeclare()
            procs.stop()
    wall = end[0] - start[0]
    ticks = end[1] - start[1]
    sim = end[2] - start[2]
    return ticks / wall, sim / wall, cpu


def _tick_time(data: bytes) -> tuple[int, float]:
    c = decode(data, Clock)
    return c.tick, c.sim_time_s


def physics_available() -> bool:
    try:
        import sim_world.physics_node  # noqa: F401
    except ImportError:
        return False
    return True


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--counts", default="1,3,8,16,32,64")
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--driver", choices=["physics", "stub", "auto"], default="auto")
    parser.add_argument("--no-plume", action="store_true", help="no plume service (no sensor)")
    parser.add_argument(
        "--per-process", type=int, default=1, help="vehicles served by each autopilot process"
    )
    args = parser.parse_args()
    driver = args.driver
    if driver == "auto":
        driver = "physics" if physics_available() else "stub"
    print("control tick cost per vehicle (in-process, hovering):")
    print(f"{'vehicle':>14} {'step µs':>9} {'node path µs':>13}")
    for vt in ("iris", "typhoon_h480"):
        step_us, path_us = control_cost(vt)
        print(f"{vt:>14} {step_us:9.1f} {path_us:13.1f}")
    per = (
        "one autopilot process per vehicle"
        if args.per_process == 1
        else (f"{args.per_process} vehicles per autopilot process")
    )
    print(f"\nlockstep, {per}, 120 Hz control, driver={driver}:")
    print(f"{'vehicles':>10} {'ticks/s':>9} {'RTF':>7} {'CPU %':>6}")
    for count in [int(c) for c in args.counts.split(",")]:
        try:
            rate, rtf, cpu = lockstep_run(
                count, args.seconds, driver, not args.no_plume, args.per_process
            )
        except Exception as exc:  # one failed row must not hide the others
            print(f"{count:>10} failed: {exc}", flush=True)
            continue
        print(f"{count:>10} {rate:9.0f} {rtf:7.2f} {cpu:6.0f}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
