"""``plumeswarm demo``: fly the scenario end to end, headless, and check the readings.

Starts the stack with the launcher (on a free loopback port, so it never meets another run),
uploads each vehicle's scenario mission, arms it and starts the mission over ``vehicle/<id>/cmd``,
shows a live table, waits (bounded) until every vehicle finished its mission and landed, then
prints for five moments per vehicle the reported concentration next to the plume model at exactly
that position, and writes ``summary.json`` (with a digest of the whole vehicle-state stream, so
two runs can be compared from outside) into the run directory.

It drives the stack through an :class:`agents.Swarm` client. By default the world runs on a
stepped clock that this client steps: the commands go out while the world is paused and land on
the next tick, and the end is checked every ``STEP_S`` of sim time, so two runs give the same
digest. ``clock = "lockstep"`` or ``"realtime"`` flies free-running instead.
"""

from __future__ import annotations

import hashlib
import json
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgspec
import numpy as np
import numpy.typing as npt

from agents import Swarm, SwarmError
from agents.swarm import Subscription
from deploy.busview import BusView, Snapshot, status_line
from deploy.console import Console
from deploy.launcher import LaunchError, missing_roles
from deploy.scaling import local_stack_scenario, scale_scenario, write_scenario
from plumeswarm.experiments.driver import BusDriver, DriverError
from swarmbus.codec import encode
from swarmbus.errors import PlumeswarmError
from swarmbus.keys import Keys
from swarmbus.messages import (
    Arm,
    Command,
    ConcentrationReading,
    MissionStart,
    MissionUpload,
    VehicleState,
    VehicleStatus,
)
from swarmbus.scenario import Scenario
from swarmbus.session import NetworkConfig
from swarmbus.views import state_key_decoder

log = logging.getLogger(__name__)

SAMPLES_PER_VEHICLE = 5
STEP_S = 0.1  # a stepped demo checks whether every vehicle is done this often (sim time)
COMMAND_TIMEOUT_S = 5.0
DEMO_ROLES = ("router", "plume", "physics", "autopilot")
AIRBORNE_M = 1.0
# The field at (N, 3) points, each at its own sim time (time-dependent plumes need it).
ModelFn = Callable[[npt.NDArray[np.float64], Sequence[float]], npt.NDArray[np.float64]]


class DemoError(PlumeswarmError, RuntimeError):
    pass


# ---------------------------------------------------------------------------- what we collect
class StateDigest:
    """SHA-256 of every vehicle-state payload, ordered by (tick, vehicle id)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._payloads: dict[tuple[int, str], bytes] = {}
        self.conflicts = 0  # same (tick, vehicle) seen with different bytes
        self.bad = 0

    def add(self, payload: bytes) -> None:
        try:
            key = state_key_decoder.decode(payload)
        except (msgspec.ValidationError, msgspec.DecodeError):
            self.bad += 1
            return
        with self._lock:
            slot = (key.tick, key.vehicle_id)
            old = self._payloads.setdefault(slot, payload)
            if old != payload:
                self.conflicts += 1

    def result(self) -> dict[str, Any]:
        with self._lock:
            items = sorted(self._payloads.items())
        h = hashlib.sha256()
        for (tick, vid), payload in items:
            h.update(f"{tick}:{vid}:{len(payload)}:".encode())
            h.update(payload)
        ticks_by_vehicle: dict[str, list[int]] = {}
        for tick, vid in (k for k, _ in items):
            ticks_by_vehicle.setdefault(vid, []).append(tick)
        missing = sum(t[-1] - t[0] + 1 - len(t) for t in ticks_by_vehicle.values() if t)
        return {
            "sha256": h.hexdigest(),
            "messages": len(items),
            "first_tick": items[0][0][0] if items else None,
            "last_tick": items[-1][0][0] if items else None,
            "missing": missing,
            "conflicts": self.conflicts,
            "undecodable": self.bad,
        }


@dataclass
class VehicleRecord:
    readings: list[ConcentrationReading] = field(default_factory=list)
    armed_seen: bool = False
    mission_finished: bool = False
    landed_after_flight: bool = False
    last_status: VehicleStatus | None = None

    def on_status(self, st: VehicleStatus) -> None:
        self.last_status = st
        if st.armed or not st.landed:
            self.armed_seen = True
        if st.mission_finished and self.armed_seen:
            self.mission_finished = True
        self.landed_after_flight = self.mission_finished and st.landed

    @property
    def done(self) -> bool:
        return self.mission_finished and self.landed_after_flight


class Collector:
    """What the demo's :class:`~agents.Swarm` client hands over (see :meth:`attach`): every
    vehicle state into the digest, every status and reading into the vehicles' records."""

    def __init__(self, vehicle_ids: Sequence[str]) -> None:
        self.digest = StateDigest()
        self._lock = threading.Lock()
        self.vehicles = {vid: VehicleRecord() for vid in vehicle_ids}
        self._subs: list[Subscription] = []

    def attach(self, swarm: Swarm) -> None:
        """Attached before the world starts, so the digest has every state from tick 0; a
        stepped ``swarm.step`` returns once the tick's states, statuses and readings went
        through, so what the demo decides on is the tick it paused at."""
        self._subs.append(
            swarm.subscribe(
                on_state=self.on_state, on_status=self.on_status, on_reading=self.on_reading
            )
        )

    def on_state(self, state: VehicleState) -> None:
        self.digest.add(encode(state))  # the bytes the physics put: one encoding, one struct

    def on_status(self, st: VehicleStatus) -> None:
        rec = self.vehicles.get(st.vehicle_id)
        if rec is not None:
            with self._lock:
                rec.on_status(st)

    def on_reading(self, r: ConcentrationReading) -> None:
        rec = self.vehicles.get(r.vehicle_id)
        if rec is not None:
            with self._lock:
                rec.readings.append(r)

    def all_done(self) -> bool:
        with self._lock:
            return all(r.done for r in self.vehicles.values())

    def close(self) -> None:
        for sub in self._subs:
            sub.close()


# ---------------------------------------------------------------------------- commands
def wait_for_world(view: BusView, vehicle_ids: Sequence[str], deadline: float) -> None:
    """Until the lockstep runs: a state past the start handshake and a status of every vehicle.

    Tick 0 is re-published until every autopilot answered it, so a state of tick 0 alone does not
    mean its autopilot has one yet (it would refuse the first command); a later tick does.
    """

    def ready(snap: Snapshot) -> bool:
        return all(
            (v := snap.vehicles.get(vid)) is not None
            and v.state is not None
            and v.state.tick >= 1
            and v.status is not None
            for vid in vehicle_ids
        )

    while not ready(snap := view.snapshot()):
        if time.monotonic() > deadline:
            missing = [vid for vid in vehicle_ids if vid not in snap.vehicles]
            raise DemoError(f"the world did not start in time (no state of {', '.join(missing)})")
        view.wait_changed(0.2)


def start_missions(sw: Swarm, scenario: Scenario, deadline: float) -> None:
    """Upload each vehicle's scenario mission, arm it and start it (an autopilot that does not
    answer yet is asked again until ``deadline``)."""
    for v in scenario.vehicles:
        uav = sw.command(v.id)
        upload: list[Command] = [MissionUpload(items=v.mission)] if v.mission else []
        for command in [*upload, Arm(), MissionStart()]:
            try:
                uav.send(command, retry_until=deadline)
            except SwarmError as exc:
                raise DemoError(str(exc)) from None


# ---------------------------------------------------------------------------- results
def model_for(scenario: Scenario) -> ModelFn:
    """The plume model the scenario describes (plume_service's own construction of it)."""
    from plume_service.from_scenario import field_from_scenario

    field_ = field_from_scenario(scenario)

    def model(points: npt.NDArray[np.float64], times: Sequence[float]) -> npt.NDArray[np.float64]:
        return np.array(
            [field_.concentration(p[None, :], t)[0] for p, t in zip(points, times, strict=True)]
        )

    return model


def pick_samples(
    readings: Sequence[ConcentrationReading], window: tuple[float, float | None], n: int
) -> list[ConcentrationReading]:
    """``n`` moments spread over the flight, preferring readings inside the sensor window."""
    airborne = [
        r
        for r in readings
        if r.available and r.reported_g_m3 is not None and r.position_enu_m[2] > AIRBORNE_M
    ]
    low, high = window
    inside = [
        r
        for r in airborne
        if r.reported_g_m3 is not None
        and r.reported_g_m3 > low
        and (high is None or r.reported_g_m3 < high)
    ]
    pool = inside if len(inside) >= n else airborne
    if len(pool) <= n:
        return list(pool)
    idx = np.linspace(0, len(pool) - 1, n).round().astype(int)
    return [pool[i] for i in idx]


def vehicle_summary(
    rec: VehicleRecord,
    final_position: Sequence[float] | None,
    model: ModelFn | None,
    window: tuple[float, float | None],
) -> dict[str, Any]:
    values = [r.reported_g_m3 for r in rec.readings if r.reported_g_m3 is not None]
    samples = pick_samples(rec.readings, window, SAMPLES_PER_VEHICLE)
    modelled: list[float | None] = [None] * len(samples)
    if model is not None and samples:
        pts = np.array([s.position_enu_m for s in samples], dtype=np.float64)
        modelled = [float(v) for v in model(pts, [s.sim_time_s for s in samples])]
    rows = [
        {
            "sim_time_s": s.sim_time_s,
            "x": s.position_enu_m[0],
            "y": s.position_enu_m[1],
            "z": s.position_enu_m[2],
            "reported_g_m3": s.reported_g_m3,
            "model_g_m3": m,
        }
        for s, m in zip(samples, modelled, strict=True)
    ]
    return {
        "mission_completed": rec.mission_finished,
        "landed": rec.landed_after_flight,
        "readings": len(rec.readings),
        "readings_unavailable": sum(1 for r in rec.readings if not r.available),
        "max_concentration_g_m3": max(values) if values else None,
        "final_position": list(final_position) if final_position is not None else None,
        "samples": rows,
    }


def accuracy_table(vehicles: dict[str, dict[str, Any]]) -> str:
    """Five moments per vehicle: position, reported, model at that position, difference."""
    head = (
        f"{'vehicle':<8} {'t [s]':>8} {'x':>7} {'y':>7} {'z':>6} "
        f"{'reported':>10} {'model':>10} {'diff':>10}"
    )
    lines = [head, "-" * len(head)]
    for vid, v in vehicles.items():
        if not v["samples"]:
            lines.append(f"{vid:<8} (no readings in flight)")
        for row in v["samples"]:
            rep, mod = row["reported_g_m3"], row["model_g_m3"]
            diff = f"{rep - mod:10.5f}" if rep is not None and mod is not None else f"{'--':>10}"
            lines.append(
                f"{vid:<8} {row['sim_time_s']:8.2f} {row['x']:7.2f} {row['y']:7.2f} "
                f"{row['z']:6.2f} {_g(rep)} {_g(mod)} {diff}"
            )
    return "\n".join(lines)


def _g(value: float | None) -> str:
    return f"{value:10.5f}" if value is not None else f"{'--':>10}"


def live_table(snap: Snapshot, records: dict[str, VehicleRecord], expected: int) -> str:
    lines = [status_line(snap, expected)]
    lines.append(
        f"{'vehicle':<8} {'mode':<9} {'arm':<4} {'item':>7} {'x':>8} {'y':>8} {'z':>7} "
        f"{'g/m3':>8}  done"
    )
    for vid, rec in records.items():
        v = snap.vehicles.get(vid)
        st = v.status if v else None
        pos = v.position if v and v.position else (float("nan"),) * 3
        r = v.reading if v else None
        item = f"{st.mission_index + 1}/{st.mission_count}" if st else "-"
        reading = f"{r.reported_g_m3:8.4f}" if r and r.reported_g_m3 is not None else f"{'--':>8}"
        mode = str(st.mode) if st else "?"
        armed = "yes" if st and st.armed else "no"
        lines.append(
            f"{vid:<8} {mode:<9} {armed:<4} "
            f"{item:>7} {pos[0]:8.2f} {pos[1]:8.2f} {pos[2]:7.2f} {reading}  "
            + ("yes" if rec.done else "")
        )
    return "\n".join(lines)


# ---------------------------------------------------------------------------- the run
@dataclass(frozen=True)
class DemoOptions:
    scenario: Scenario
    scenario_path: Path
    out: Path
    vehicles: int | None = None
    timeout_s: float = 900.0
    table_period_s: float = 1.0
    attach: tuple[str, ...] = ()  # fly a stack already running behind this router endpoint
    network: NetworkConfig | None = None  # how to join it (default: the scenario's, e.g. TLS)
    record: bool = True  # run the recorder too, when it is installed
    # "stepped" (default for its own stack: reproducible), "lockstep" or "realtime";
    # None with ``attach``: however the attached world runs
    clock: str | None = None


def prepare(opts: DemoOptions) -> tuple[Scenario, Path]:
    """The scenario to fly (scaled, with a free router port) written into the run directory."""
    sc = opts.scenario
    if opts.vehicles is not None:
        sc = scale_scenario(sc, opts.vehicles)
    if opts.attach:
        return sc, write_scenario(sc, opts.out / "scenario.toml")
    return local_stack_scenario(sc, opts.out, opts.clock or "stepped")


def clock_mode(view: BusView, deadline: float) -> str:
    """How the (attached) world's clock runs, from its ``sim/clock``."""
    while (snap := view.snapshot()).clock is None:
        if time.monotonic() > deadline:
            raise DemoError("no sim/clock from the physics in time")
        view.wait_changed(0.2)
    return str(snap.clock.mode)


def start_stepped(driver: BusDriver, sc: Scenario, deadline: float) -> Callable[[], None]:
    """Start the missions on a stepped clock; returns how to advance the world: every command
    lands on a known tick, and the run ends on the first check (every ``STEP_S`` of sim time)
    that finds every vehicle done, so two runs give the same state stream."""
    driver.step(1)  # past the start handshake: every autopilot has its first state
    start_missions(driver.swarm, sc, deadline)  # paused at tick 1: they take effect in tick 2
    ticks = max(1, round(STEP_S * sc.time.control_hz))

    def advance() -> None:
        driver.step(ticks)

    return advance


def start_free(view: BusView, sw: Swarm, sc: Scenario, deadline: float) -> Callable[[], None]:
    """Start the missions on a free-running clock (lockstep or realtime): commands land on
    whichever tick is current when they arrive; returns how to wait for news."""
    wait_for_world(view, [v.id for v in sc.vehicles], deadline)
    start_missions(sw, sc, deadline)

    def advance() -> None:
        view.wait_changed(0.2)

    return advance


@dataclass
class DemoRun:
    """What a run saw: the collector's records, the clock's mode, the last snapshot of the bus,
    and the wall time (from the missions' start) and sim time it took."""

    collector: Collector
    mode: str
    snap: Snapshot | None = None
    wall0: float = field(default_factory=time.monotonic)
    wall_s: float = 0.0
    sim0: float | None = None


def run_demo(opts: DemoOptions, console: Console) -> int:
    sc, path = prepare(opts)
    record = opts.record and not opts.attach and not missing_roles(["recorder"])
    console.line(f"plumeswarm demo: {len(sc.vehicles)} vehicle(s), run directory {opts.out}")
    flight = fly(opts, sc, record, console)
    if flight is None:
        return 1
    return finish(opts, sc, path, flight, record, console)


def fly(opts: DemoOptions, sc: Scenario, record: bool, console: Console) -> DemoRun | None:
    """Start the world (our own stack: what flying needs, no gateway since nobody speaks
    MAVLink here, the recorder when it is installed; or the attached one) through a
    :class:`~plumeswarm.experiments.driver.BusDriver`, fly every mission to its end (or the
    deadline),
    stop; None when it never reached the bus."""
    flight = DemoRun(Collector([v.id for v in sc.vehicles]), mode=opts.clock or sc.time.mode)
    views: list[BusView] = []

    def on_join(sw: Swarm) -> None:  # before the world starts: states from tick 0
        flight.collector.attach(sw)
        views.append(BusView(sw.session, Keys(sc.world.name)))

    driver = BusDriver(
        attach=opts.attach or None,
        run_dir=opts.out,
        startup_timeout_s=sc.time.startup_timeout_s,
        mode=opts.clock or "stepped",
        roles=DEMO_ROLES + (("recorder",) if record else ()),
        record=record,
        network=opts.network,
        on_join=on_join,
    )
    deadline = time.monotonic() + opts.timeout_s
    try:
        driver.start(sc)
        fly_missions(opts, sc, driver, views[0], flight, console, deadline)
    except (LaunchError, DriverError, DemoError, SwarmError) as exc:
        console.line(f"plumeswarm demo: {exc}")
    finally:
        flight.wall_s = time.monotonic() - flight.wall0
        for view in views:
            view.close()
        driver.close()
        flight.collector.close()
    return flight if views else None


def fly_missions(
    opts: DemoOptions,
    sc: Scenario,
    driver: BusDriver,
    view: BusView,
    flight: DemoRun,
    console: Console,
    deadline: float,
) -> None:
    """Start the missions on the world's clock and advance it until every vehicle is done."""
    console.line(f"plumeswarm demo: {len(view.presence.alive)} processes ready")
    if opts.attach:
        flight.mode = opts.clock or clock_mode(view, deadline)
    console.line(f"plumeswarm demo: {flight.mode} clock; starting missions")
    if flight.mode == "stepped":
        advance = start_stepped(driver, sc, deadline)
    else:
        advance = start_free(view, driver.swarm, sc, deadline)
    flight.wall0 = time.monotonic()
    flight.snap = view.snapshot()
    flight.sim0 = flight.snap.clock.sim_time_s if flight.snap.clock else None
    show = table_shower(opts, console, view, flight.collector)
    while not flight.collector.all_done():
        driver.supervise_once()
        if time.monotonic() > deadline:
            break
        show()
        advance()
    flight.snap = view.snapshot()


def table_shower(
    opts: DemoOptions, console: Console, view: BusView, collector: Collector
) -> Callable[[], None]:
    """Shows the live table every ``table_period_s`` (every 10 s when not on a terminal)."""
    period_s = opts.table_period_s if console.tty else 10.0
    next_at = [0.0]

    def show() -> None:
        now = time.monotonic()
        if now >= next_at[0]:
            console.block(live_table(view.snapshot(), collector.vehicles, len(collector.vehicles)))
            next_at[0] = now + period_s

    return show


def finish(
    opts: DemoOptions, sc: Scenario, path: Path, flight: DemoRun, record: bool, console: Console
) -> int:
    """Write ``summary.json``, print the accuracy table and the verdict; the exit code."""
    collector = flight.collector
    if flight.snap is not None:
        console.block(live_table(flight.snap, collector.vehicles, len(sc.vehicles)))
    summary = build_summary(
        sc, path, collector, flight.snap, flight.wall_s, flight.sim0, record, opts.out
    )
    summary["clock"] = flight.mode
    summary["deterministic"] = flight.mode == "stepped"
    (opts.out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    console.line("")
    console.line(accuracy_table(summary["vehicles"]))
    console.line("")
    rtf = summary["real_time_factor"]
    console.line(
        f"real-time factor {rtf:.2f}x, state digest {summary['state_digest']['sha256'][:16]}… "
        f"({summary['state_digest']['messages']} states); summary {opts.out / 'summary.json'}"
        if rtf is not None
        else f"summary {opts.out / 'summary.json'}"
    )
    console.line(
        "plumeswarm demo: deterministic: stepped clock (the same run gives the same state digest)"
        if flight.mode == "stepped"
        else f"plumeswarm demo: not deterministic: {flight.mode} clock (commands land on whichever "
        "tick is current)"
    )
    failed = [
        vid
        for vid, v in summary["vehicles"].items()
        if not (v["mission_completed"] and v["landed"])
    ]
    if failed:
        console.line(f"plumeswarm demo: FAILED: not completed and landed: {', '.join(failed)}")
        return 1
    console.line("plumeswarm demo: every vehicle completed its mission and landed")
    return 0


def build_summary(
    sc: Scenario,
    path: Path,
    collector: Collector,
    snap: Snapshot | None,
    wall_s: float,
    sim0: float | None,
    recorded: bool,
    out: Path,
    model: ModelFn | None = None,
) -> dict[str, Any]:
    if model is None:
        try:
            model = model_for(sc)
        except ImportError:
            log.warning("plume_service is not installed: no model column")
    sensor = sc.sensor.resolved()
    window = (sensor.detection_limit_g_m3, sensor.saturation_g_m3)
    sim_end = snap.clock.sim_time_s if snap is not None and snap.clock is not None else None
    rtf = (
        (sim_end - sim0) / wall_s
        if sim_end is not None and sim0 is not None and wall_s > 0
        else None
    )
    vehicles = {}
    for vid, rec in collector.vehicles.items():
        view = snap.vehicles.get(vid) if snap is not None else None
        vehicles[vid] = vehicle_summary(rec, view.position if view else None, model, window)
    recording = out / "recording.mcap"
    return {
        "scenario": {
            "path": str(path),
            "world": sc.world.name,
            "seed": sc.world.seed,
            "vehicles": len(sc.vehicles),
            "physics_hz": sc.time.physics_hz,
            "control_hz": sc.time.control_hz,
        },
        "real_time_factor": rtf,
        "sim_time_s": sim_end,
        "wall_time_s": wall_s,
        "state_digest": collector.digest.result(),
        "recording": str(recording) if recorded and recording.exists() else None,
        "ok": all(v["mission_completed"] and v["landed"] for v in vehicles.values()),
        "vehicles": vehicles,
    }
