"""``plumeswarm bench scale``: real-time factor, CPU and memory of the full stack against vehicle
count, grounded, hovering and flying. Each row's stack is started and commanded by a
:class:`~plumeswarm.experiments.driver.BusDriver` that only commands (``follow=False``: the bench
watches
the clock and the statuses itself, nothing else). See docs/performance.md ("What the bench
does").
"""

from __future__ import annotations

import json
import logging
import os
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgspec
import psutil
import zenoh

from agents import SwarmError, VehicleCommander
from deploy.launcher import Launcher, LaunchError
from deploy.scaling import (
    ScalingError,
    flight_altitude,
    local_stack_scenario,
    loop_mission,
    multirotors_only,
    scale_scenario,
)
from deploy.up import stop_on_signals
from plumeswarm.experiments.driver import BusDriver, Driver, DriverError
from swarmbus.codec import MessageError, decode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import (
    Arm,
    Clock,
    Command,
    MissionStart,
    MissionUpload,
    Takeoff,
    VehicleStatus,
)
from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

STATES = ("grounded", "hovering", "flying")
ROLES = ("router", "plume", "physics", "autopilot", "gateway")
SAMPLE_PERIOD_S = 0.5
WARMUP_S = 1.0  # wall time between reaching the state and the window (start-up transients)
AIRBORNE_M = 1.0
COMMAND_TIMEOUT_S = 5.0  # one command's answer


class ScaleError(PlumeswarmError, RuntimeError):
    pass


@dataclass(frozen=True)
class ScaleOptions:
    scenario: Scenario
    out: Path
    vehicles: tuple[int, ...] = (1, 2, 4, 8, 16, 32, 64)
    states: tuple[str, ...] = STATES
    seconds: float = 10.0
    vehicles_per_process: int = 1
    gateway: bool = True
    startup_timeout_s: float = 120.0
    sensor_period_ticks: int | None = None  # None: the scenario's own sensor rate
    baseline: bool = False  # also measure each row's ceiling (deploy.ceiling), back to back
    # the ROS 2 bridge: "off", "idle" (no ROS 2 subscriber) or "subscribed" (one subscriber,
    # of the bench's own, to every topic it publishes on ROS domain 0)
    ros2: str = "off"


# The roles whose processes the ceiling replaces with stand-ins doing no work (the router stays).
CEILING = {
    "physics": "ceiling-physics",
    "autopilot": "ceiling-autopilot",
    "plume": "ceiling-plume",
    "gateway": "ceiling-gateway",
}


# ---------------------------------------------------------------------------- scenario
def bench_scenario(sc: Scenario, n: int, sensor_period_ticks: int | None = None) -> Scenario:
    """``sc`` with ``n`` vehicles (with the sensor every ``sensor_period_ticks`` control ticks
    when given)."""
    sc = scale_scenario(sc, n)
    if sensor_period_ticks is not None:
        sensor = msgspec.structs.replace(sc.sensor, period_ticks=sensor_period_ticks)
        sc = msgspec.structs.replace(sc, sensor=sensor)
    return sc


def prepare(
    sc: Scenario, n: int, run_dir: Path, sensor_period_ticks: int | None = None
) -> tuple[Scenario, Path]:
    """:func:`bench_scenario` in lockstep, on a free router port, written into run_dir."""
    sc = bench_scenario(sc, n, sensor_period_ticks)
    return local_stack_scenario(sc, run_dir, "lockstep", startup_timeout_s=120.0)


# ---------------------------------------------------------------------------- observation
class Watch:
    """The latest clock (with its arrival time) and each vehicle's latest status."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self.lock = threading.Lock()
        self.changed = threading.Condition(self.lock)
        self.clock: tuple[float, Clock] | None = None
        self.status: dict[str, VehicleStatus] = {}
        self._subs = [
            session.declare_subscriber(keys.clock(), self._on_clock),
            session.declare_subscriber(keys.all_vehicle_status(), self._on_status),
        ]

    def _on_clock(self, sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            clock = decode(sample.payload.to_bytes(), Clock)
        except MessageError:
            return
        with self.lock:
            self.clock = (now, clock)
            self.changed.notify_all()

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            vid = self.keys.vehicle_id_of(str(sample.key_expr))
            st = decode(sample.payload.to_bytes(), VehicleStatus)
        except (KeyNameError, MessageError):
            return
        with self.lock:
            self.status[vid] = st
            self.changed.notify_all()

    def wait(self, pred: Callable[[Watch], bool], deadline: float, what: str) -> None:
        with self.lock:
            while not pred(self):
                left = deadline - time.monotonic()
                if left <= 0:
                    raise ScaleError(f"timed out waiting for {what}")
                self.changed.wait(min(left, 0.5))

    def next_clock(self, after: float, deadline: float) -> tuple[float, Clock]:
        """The first clock that arrives after monotonic time ``after``."""
        self.wait(lambda w: w.clock is not None and w.clock[0] > after, deadline, "sim/clock")
        assert self.clock is not None
        return self.clock

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


def _airborne(ids: Sequence[str]) -> Callable[[Watch], bool]:
    def pred(w: Watch) -> bool:
        return all((s := w.status.get(v)) is not None and s.armed and not s.landed for v in ids)

    return pred


class RoleUsage:
    """CPU seconds and peak RSS per role over a window (processes and their children)."""

    def __init__(self, pids_by_role: dict[str, list[int]]) -> None:
        self.procs: dict[str, list[psutil.Process]] = {}
        for role, pids in pids_by_role.items():
            procs = []
            for pid in pids:
                try:
                    p = psutil.Process(pid)
                    procs += [p, *p.children(recursive=True)]
                except psutil.Error:
                    continue
            self.procs[role] = procs
        self.cpu0 = self._cpu()
        self.peak_rss: dict[str, float] = {r: 0.0 for r in self.procs}

    def _cpu(self) -> dict[str, float]:
        out = {}
        for role, procs in self.procs.items():
            total = 0.0
            for p in procs:
                try:
                    t = p.cpu_times()
                    total += t.user + t.system
                except psutil.Error:
                    continue
            out[role] = total
        return out

    def sample_rss(self) -> None:
        for role, procs in self.procs.items():
            total = 0
            for p in procs:
                try:
                    total += p.memory_info().rss
                except psutil.Error:
                    continue
            self.peak_rss[role] = max(self.peak_rss[role], total / 2**20)

    def cpu_seconds(self) -> dict[str, float]:
        cpu1 = self._cpu()
        return {r: cpu1[r] - self.cpu0[r] for r in self.procs}


# ---------------------------------------------------------------------------- one case
def state_commands(sc: Scenario, state: str) -> dict[str, list[Command]]:
    """What puts every vehicle of ``sc`` into ``state``, in order (``grounded``: nothing;
    ``hovering``: arm and take off; ``flying``: a looping square mission)."""
    commands: dict[str, list[Command]] = {}
    for k, v in enumerate(sc.vehicles):
        commands[v.id] = []
        if state == "hovering":
            commands[v.id] = [Arm(), Takeoff(altitude_m=flight_altitude(sc, k))]
        elif state == "flying":
            commands[v.id] = [MissionUpload(items=loop_mission(sc, k)), Arm(), MissionStart()]
    return commands


def drive(session: zenoh.Session, sc: Scenario, state: str, deadline: float) -> None:
    """Command every vehicle of ``sc`` into ``state`` on ``session`` (a stack started without a
    driver), each command retried until ``deadline`` while its autopilot does not answer."""
    keys = Keys(sc.world.name)
    for vid, commands in state_commands(sc, state).items():
        uav = VehicleCommander(session, keys, vid, COMMAND_TIMEOUT_S)
        for command in commands:
            uav.send(command, retry_until=deadline)


def command_into(driver: Driver, sc: Scenario, state: str) -> None:
    """Command every vehicle of ``sc`` into ``state`` through ``driver`` (its world past the start
    handshake: every autopilot takes commands): the first command of every vehicle at once,
    then the second, ...; a refusal is a :class:`ScaleError`."""
    plan = state_commands(sc, state)
    for commands in zip(*plan.values(), strict=True):
        batch = list(zip(plan, commands, strict=True))
        for (vid, command), reply in zip(batch, driver.command(batch), strict=True):
            if not reply.accepted:
                raise ScaleError(f"{vid}: {type(command).__name__}: {reply.reason}")


def _roles(opts: ScaleOptions, ceiling: bool) -> tuple[str, ...]:
    roles = tuple(r for r in ROLES if r != "gateway" or opts.gateway)
    return (*roles, "ros2") if opts.ros2 != "off" and not ceiling else roles


def _ros2_subscriber(
    opts: ScaleOptions, launcher: Launcher, ceiling: bool
) -> zenoh.Subscriber[None] | None:
    """With ``--ros2 subscribed``: a ROS 2 subscriber of every topic on ROS domain 0 (the
    samples are dropped)."""
    if opts.ros2 != "subscribed" or ceiling:
        return None
    return launcher.session.declare_subscriber("0/**", lambda _: None)


def run_case(
    opts: ScaleOptions,
    n: int,
    state: str,
    stop: threading.Event | None = None,
    ceiling: bool = False,
) -> dict[str, Any]:
    """One row: the stack with ``n`` vehicles in ``state``, or (``ceiling``) the same processes
    replaced by the stand-ins of :mod:`deploy.ceiling` (nothing is driven: they do no work)."""
    sc = bench_scenario(opts.scenario, n, opts.sensor_period_ticks)
    ids = [v.id for v in sc.vehicles]
    # A driver that only commands: it follows no state, so the bench adds no subscriber of every
    # state to the stack it measures (it watches the clock and the statuses, below).
    driver = BusDriver(
        run_dir=opts.out / (f"ceiling-{n}" if ceiling else f"{state}-{n}"),
        vehicles_per_process=opts.vehicles_per_process,
        startup_timeout_s=opts.startup_timeout_s,
        mode="lockstep",
        roles=_roles(opts, ceiling),
        stand_ins=CEILING if ceiling else {},
        follow=False,
    )
    deadline = time.monotonic() + opts.startup_timeout_s
    watch: Watch | None = None
    ros2_subscriber: zenoh.Subscriber[None] | None = None
    keys = Keys(sc.world.name)
    try:
        driver.start(sc)
        launcher = driver.launcher
        assert launcher is not None
        watch = Watch(launcher.session, keys)
        ros2_subscriber = _ros2_subscriber(opts, launcher, ceiling)
        watch.wait(lambda w: len(w.status) >= len(ids), deadline, "every vehicle's status")
        watch.next_clock(time.monotonic(), deadline)
        if not ceiling:
            command_into(driver, sc, state)
        if state != "grounded" and not ceiling:
            watch.wait(_airborne(ids), deadline, "every vehicle airborne")
        time.sleep(WARMUP_S)
        by_role: dict[str, list[int]] = {}
        pids = launcher.supervisor.pids()
        for spec in launcher.specs:
            if spec.name in pids:
                by_role.setdefault(spec.role, []).append(pids[spec.name])
        usage = RoleUsage(by_role)
        t0, c0 = watch.next_clock(time.monotonic(), deadline)
        cpu_t0 = time.monotonic()
        end = cpu_t0 + opts.seconds
        while time.monotonic() < end:
            if stop is not None and stop.is_set():
                raise ScaleError("interrupted")
            usage.sample_rss()
            driver.supervise_once()
            time.sleep(min(SAMPLE_PERIOD_S, max(0.0, end - time.monotonic())))
        t1, c1 = watch.next_clock(time.monotonic() - 1e-3, time.monotonic() + 30.0)
        cpu_wall = time.monotonic() - cpu_t0
        cpu_s = usage.cpu_seconds()
        cpu = {r: round(100.0 * s / cpu_wall, 1) for r, s in cpu_s.items()}
        usage.sample_rss()
        load1 = os.getloadavg()[0]
        wall = t1 - t0
        ticks_per_s = (c1.tick - c0.tick) / wall
        ticks = max(ticks_per_s * cpu_wall, 1.0)  # ticks in the CPU window
        per_tick = {r: round(1e3 * s / ticks, 3) for r, s in cpu_s.items()}
        return {
            "vehicles": n,
            "state": state,
            "vehicles_per_process": opts.vehicles_per_process,
            "control_hz": sc.time.control_hz,
            "physics_hz": sc.time.physics_hz,
            "sensor_period_ticks": sc.sensor.resolved().period_ticks,
            "real_time_factor": round((c1.sim_time_s - c0.sim_time_s) / wall, 3),
            "ticks_per_s": round(ticks_per_s, 1),
            "cpu_percent_by_role": cpu,
            "cpu_percent_total": round(sum(cpu.values()), 1),
            "cpu_ms_per_tick_by_role": per_tick,
            "cpu_ms_per_tick_total": round(sum(per_tick.values()), 3),
            "load1": round(load1, 2),
            "peak_rss_mb_by_role": {r: round(v, 1) for r, v in usage.peak_rss.items()},
            "wall_s": round(wall, 2),
            "ros2": opts.ros2,
        }
    finally:
        if ros2_subscriber is not None:
            ros2_subscriber.undeclare()
        if watch is not None:
            watch.close()
        driver.close()


# ---------------------------------------------------------------------------- output
TABLE_CPU = ("physics", "autopilot", "plume", "gateway", "router", "ros2")


def markdown(rows: Sequence[dict[str, Any]]) -> str:
    head = (
        "| N | state | K | RTF | ticks/s | ceiling ticks/s | fraction of ceiling | CPU % total | "
        + " | ".join(f"CPU % {r}" for r in TABLE_CPU)
        + " | CPU ms/tick total | "
        + " | ".join(f"ms/tick {r}" for r in TABLE_CPU)
        + " | load1 | RSS MB autopilots | RSS MB physics |"
    )
    lines = [head, "|" + "---|" * (head.count("|") - 1)]
    for r in rows:
        if "error" in r:
            lines.append(f"| {r['vehicles']} | {r['state']} | error: {r['error']} |")
            continue
        cpu, rss = r["cpu_percent_by_role"], r["peak_rss_mb_by_role"]
        per_tick = r.get("cpu_ms_per_tick_by_role", {})
        cells = [
            str(r["vehicles"]),
            r["state"],
            str(r["vehicles_per_process"]),
            f"{r['real_time_factor']:.2f}",
            f"{r['ticks_per_s']:.0f}",
            f"{r['ceiling_ticks_per_s']:.0f}" if "ceiling_ticks_per_s" in r else "–",
            f"{r['fraction_of_ceiling']:.2f}" if "fraction_of_ceiling" in r else "–",
            f"{r['cpu_percent_total']:.0f}",
            *(f"{cpu.get(k, 0.0):.0f}" for k in TABLE_CPU),
            f"{r.get('cpu_ms_per_tick_total', 0.0):.3f}",
            *(f"{per_tick.get(k, 0.0):.3f}" for k in TABLE_CPU),
            f"{r['load1']:.2f}",
            f"{rss.get('autopilot', 0.0):.0f}",
            f"{rss.get('physics', 0.0):.0f}",
        ]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plots(rows: Sequence[dict[str, Any]], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    good = [r for r in rows if "error" not in r]
    written = []
    for name, key, label in (
        ("rtf.png", "real_time_factor", "real-time factor"),
        ("cpu.png", "cpu_percent_total", "CPU % (100 = one core)"),
    ):
        fig, ax = plt.subplots(figsize=(6, 4))
        for state in STATES:
            pts = sorted((r["vehicles"], r[key]) for r in good if r["state"] == state)
            if pts:
                ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=state)
        ax.set_xscale("log", base=2)
        ax.set_xlabel("vehicles")
        ax.set_ylabel(label)
        if key == "real_time_factor":
            ax.axhline(1.0, color="grey", linewidth=0.8, linestyle="--")
        ax.grid(True, alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / name, dpi=100)
        plt.close(fig)
        written.append(out / name)
    return written


def run_scale(opts: ScaleOptions, echo: Callable[[str], None] = print) -> list[dict[str, Any]]:
    from tqdm import tqdm

    unknown = [s for s in opts.states if s not in STATES]
    if unknown:
        raise ScaleError(f"unknown state(s) {', '.join(unknown)}; states: {', '.join(STATES)}")
    try:
        multirotors_only(opts.scenario, "bench scale flies every vehicle in 3 m squares")
    except ScalingError as exc:
        raise ScaleError(str(exc)) from None
    opts.out.mkdir(parents=True, exist_ok=True)
    cases = [(n, s) for n in opts.vehicles for s in opts.states]
    rows: list[dict[str, Any]] = []
    with stop_on_signals() as stop:
        bar = tqdm(cases, desc="bench scale", unit="case")
        for n, state in bar:
            if stop.is_set():
                break
            rows.append(_one(opts, n, state, stop, bar))
            (opts.out / "scale.json").write_text(json.dumps(rows, indent=2) + "\n")
    (opts.out / "scale.md").write_text(markdown(rows))
    plots(rows, opts.out)
    echo(markdown(rows))
    echo(f"written: {opts.out / 'scale.json'}, scale.md, rtf.png, cpu.png")
    return rows


def _one(opts: ScaleOptions, n: int, state: str, stop: threading.Event, bar: Any) -> dict[str, Any]:
    bar.set_postfix_str(f"{n} {state}")
    try:
        row = run_case(opts, n, state, stop)
    except (LaunchError, DriverError, ScaleError, SwarmError) as exc:
        row = {"vehicles": n, "state": state, "error": str(exc)}
    if opts.baseline and "error" not in row:
        bar.set_postfix_str(f"{n} {state} ceiling")
        add_ceiling(row, _ceiling_ticks_per_s(opts, n, stop))
    bar.write(
        f"{n:4d} {state:<9} "
        + (
            f"RTF {row['real_time_factor']:6.2f}  {row['ticks_per_s']:6.0f} ticks/s  "
            f"CPU {row['cpu_percent_total']:5.0f} %  "
            f"{row['cpu_ms_per_tick_total']:.3f} CPU ms/tick  load1 {row['load1']:.2f}"
            + (
                f"  ceiling {row['ceiling_ticks_per_s']:.0f} ticks/s "
                f"({row['fraction_of_ceiling']:.2f})"
                if row.get("ceiling_ticks_per_s")
                else ""
            )
            if "error" not in row
            else f"error: {row['error']}"
        )
    )
    return row


def _ceiling_ticks_per_s(opts: ScaleOptions, n: int, stop: threading.Event) -> dict[str, Any] | str:
    """The ceiling's row for ``n`` vehicles, or why it could not be measured."""
    try:
        return run_case(opts, n, "grounded", stop, ceiling=True)
    except (LaunchError, DriverError, ScaleError, SwarmError) as exc:
        return str(exc)


def add_ceiling(row: dict[str, Any], ceiling: dict[str, Any] | str) -> None:
    """``ceiling_ticks_per_s``, ``fraction_of_ceiling`` (the row's ticks/s over it) and the
    ceiling's ``ceiling_cpu_ms_per_tick_by_role`` on ``row``; ``ceiling_error`` instead when the
    ceiling run failed."""
    if isinstance(ceiling, str):
        row["ceiling_error"] = ceiling
        return
    rate = float(ceiling["ticks_per_s"])
    row["ceiling_ticks_per_s"] = round(rate, 1)
    row["fraction_of_ceiling"] = round(row["ticks_per_s"] / rate, 3) if rate > 0 else 0.0
    row["ceiling_cpu_ms_per_tick_by_role"] = ceiling["cpu_ms_per_tick_by_role"]
