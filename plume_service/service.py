"""``plumeswarm node plume``: the concentration field on the bus: the sensors' values of every
sensor tick (a lockstep participant, :class:`SensorAnswers`) and the ``plume/concentration``,
``plume/info`` and ``plume/mesh`` queryables. See docs/plume.md and docs/architecture.md ("How a
tick flows").
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import queue
import threading
from collections.abc import Callable

import msgspec
import numpy as np
import zenoh

from plume_service.field import ConcentrationField, FloatArray, PlumeField
from plume_service.filament import FilamentPlume
from plume_service.from_scenario import field_from_scenario
from plume_service.gaussian import GaussianPlume
from plume_service.mesh import isosurface
from plume_service.puff import PuffPlume
from plume_service.timestepped import TimeSteppedField
from swarmbus.codec import decode_or_none, encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Clock,
    FieldSample,
    PlumeInfo,
    PlumeInfoQuery,
    PlumeMesh,
    PlumeMeshQuery,
    PlumeQuery,
    PlumeSource,
    PlumeState,
    PlumeValues,
    Vec3,
)
from swarmbus.node import NodeContext, NodeRuntime
from swarmbus.options import RoleOptions, role_main
from swarmbus.reqrep import Incoming, serve, serve_later
from swarmbus.scenario import Scenario
from swarmbus.session import SINGLE_THREAD_RUNTIME, payload_or_none
from swarmbus.views import TickView, state_head_decoder

log = logging.getLogger(__name__)

#: Largest mesh grid served over the bus (points); finer requests are refused, not attempted.
MAX_MESH_GRID_POINTS = 20_000_000
#: Up to this many points, σ use is noted in scalar maths (numpy's per-call cost dominates).
SCALAR_NOTE_POINTS = 16


class PlumeService:
    """Answers plume queries for one field; pure request → reply functions, bus-agnostic.

    ``scenario`` (optional) names the wind model and the plume section in ``plume/info``.
    """

    def __init__(self, field: ConcentrationField, scenario: Scenario | None = None) -> None:
        self.field = field
        self.scenario = scenario
        self.sigma_use = SigmaUse(field)

    def concentration(self, query: PlumeQuery) -> PlumeValues:
        if not query.points_enu_m:
            return PlumeValues(values_g_m3=[], sim_time_s=query.sim_time_s)
        points = np.asarray(query.points_enu_m, dtype=np.float64)
        values = self.field.concentration(points, query.sim_time_s)
        self.sigma_use.note(points, values)
        return PlumeValues(values_g_m3=values.tolist(), sim_time_s=query.sim_time_s)

    def sample(self, tick: int, sim_time_s: float, points: list[Vec3]) -> FieldSample:
        """The sensors' values of one sensor tick: the concentration at ``points`` (every
        state's position, in order) at the tick's sim time."""
        query = PlumeQuery(points_enu_m=points, sim_time_s=sim_time_s)
        values = self.concentration(query).values_g_m3
        return FieldSample(tick=tick, sim_time_s=sim_time_s, values_g_m3=values)

    def info(self, _query: PlumeInfoQuery) -> PlumeInfo:
        sources = source_fields(self.field)
        models = sorted({_model_name(f) for f in sources})
        curves = [f.dispersion for f in sources if isinstance(f, GaussianPlume | PuffPlume)]
        gaussians = [f for f in sources if isinstance(f, GaussianPlume)]
        plume = self.scenario.plume if self.scenario is not None else None
        if self.scenario is not None:
            speed, from_deg = self.scenario.wind.speed_m_s, self.scenario.wind.from_deg
            wind_model = self.scenario.wind.model
        elif gaussians:
            speed, from_deg = gaussians[0].wind_speed_m_s, gaussians[0].wind_from_deg
            wind_model = "steady"
        else:
            raise ValueError("plume/info of a filament or puff field needs its scenario")
        lid = plume.mixing_height_m if plume is not None else gaussians[0].mixing_height_m
        return PlumeInfo(
            model="+".join(models),
            stability=curves[0].stability if curves else "",
            coefficients=curves[0].family if curves else "",
            wind_speed_m_s=speed,
            wind_from_deg=from_deg,
            mixing_height_m=lid,
            sources=[_plume_source(f) for f in sources],
            wind_model=wind_model,
            time_dependent=any(isinstance(f, TimeSteppedField) for f in sources),
            sigma_validity=self.sigma_use.notes(),
        )

    def mesh(self, query: PlumeMeshQuery) -> PlumeMesh:
        bounds = None
        if query.bounds_min_m is not None and query.bounds_max_m is not None:
            lo, hi = query.bounds_min_m, query.bounds_max_m
            if any(h <= lo_ for lo_, h in zip(lo, hi, strict=True)):
                raise ValueError("bounds_max_m must exceed bounds_min_m on every axis")
            bounds = ((lo[0], hi[0]), (lo[1], hi[1]), (lo[2], hi[2]))
        if bounds is not None:
            cells = np.prod([(b[1] - b[0]) / query.resolution_m + 1 for b in bounds])
            if cells > MAX_MESH_GRID_POINTS:
                raise ValueError(
                    f"grid of {cells:.3g} points exceeds {MAX_MESH_GRID_POINTS}; "
                    "use a coarser resolution_m"
                )
        vertices, faces = isosurface(self.field, query.level_g_m3, bounds, query.resolution_m)
        return PlumeMesh(
            level_g_m3=query.level_g_m3,
            vertices_f32=np.asarray(vertices, dtype="<f4").tobytes(),
            faces_i32=np.asarray(faces, dtype="<i4").tobytes(),
        )


def source_fields(field: ConcentrationField) -> list[ConcentrationField]:
    """The one-source fields a field is made of (itself, or the members of a PlumeField)."""
    if isinstance(field, PlumeField):
        return [member for source in field.sources for member in source_fields(source)]
    return [field]


def _model_name(field: ConcentrationField) -> str:
    if isinstance(field, FilamentPlume):
        return "filament"
    if isinstance(field, PuffPlume):
        return "puff"
    return "gaussian"


def _plume_source(field: ConcentrationField) -> PlumeSource:
    if isinstance(field, GaussianPlume):
        (x, y), height = field.source_m, field.release_height_m
    elif isinstance(field, TimeSteppedField):
        x, y, height = field.source_m
    else:
        raise ValueError(f"a field of type {type(field).__name__} has no source")
    return PlumeSource(
        x_m=x, y_m=y, release_rate_g_s=field.release_rate_g_s, release_height_m=height
    )


class SigmaUse:
    """Where the σ fits of a field's Gaussian and puff sources were used: the range of
    downwind distances (horizontal distance from the source for puffs) of the points that had
    a value, per source, for ``plume/info``'s ``sigma_validity``."""

    def __init__(self, field: ConcentrationField) -> None:
        self.sources = [f for f in source_fields(field) if isinstance(f, GaussianPlume | PuffPlume)]
        self._gaussian_only = all(isinstance(f, GaussianPlume) for f in self.sources)
        self._range: dict[int, tuple[float, float]] = {}
        self._lock = threading.Lock()

    def note(self, points: FloatArray, values: FloatArray) -> None:
        if not self.sources:
            return
        if self._gaussian_only and points.shape[0] <= SCALAR_NOTE_POINTS:
            self._note_few(points, values)
            return
        seen = points[values > 0.0]
        if seen.shape[0] == 0:
            return
        for index, source in enumerate(self.sources):
            if isinstance(source, GaussianPlume):
                distance = source.to_plume_frame(seen)[0]
            else:
                distance = np.hypot(
                    seen[:, 0] - source.source_m[0], seen[:, 1] - source.source_m[1]
                )
            distance = distance[distance > 0.0]
            if distance.size == 0:
                continue
            self._widen(index, float(distance.min()), float(distance.max()))

    def _note_few(self, points: FloatArray, values: FloatArray) -> None:
        """:meth:`note` for a few points and Gaussian sources, in scalar maths: the downwind
        distance (x − x₀)·uₓ + (y − y₀)·u_y as the plume frame computes it, without numpy's
        per-call cost (a sensor tick of a few vehicles)."""
        seen = [
            (p[0], p[1]) for p, v in zip(points.tolist(), values.tolist(), strict=True) if v > 0.0
        ]
        if not seen:
            return
        for index, source in enumerate(self.sources):
            assert isinstance(source, GaussianPlume)
            (x0, y0), (ux, uy) = source.source_m, source.downwind_unit
            distance = [d for x, y in seen if (d := (x - x0) * ux + (y - y0) * uy) > 0.0]
            if distance:
                self._widen(index, min(distance), max(distance))

    def _widen(self, index: int, lo: float, hi: float) -> None:
        with self._lock:
            old = self._range.get(index)
            self._range[index] = (lo, hi) if old is None else (min(old[0], lo), max(old[1], hi))

    def notes(self) -> list[str]:
        out = []
        with self._lock:
            ranges = dict(self._range)
        for index, (lo, hi) in sorted(ranges.items()):
            curves = self.sources[index].dispersion
            valid_lo, valid_hi = curves.valid_range_m
            if lo < valid_lo or hi > valid_hi:
                out.append(
                    f"source {index}: {curves.family} class {curves.stability} σ used at "
                    f"{lo:.3g}–{hi:.3g} m downwind, outside the {valid_lo:g}–{valid_hi:g} m "
                    "the fit was published for (values there are extrapolated)"
                )
        return out


class StatePublisher:
    """Publishes the filaments or puffs of a time-dependent field every ``period_s`` of sim
    time, following the physics' clock; the state published for sim time t is the field's
    state at t, whoever asks and whenever."""

    def __init__(self, field: ConcentrationField, period_s: float) -> None:
        self.sources = [f for f in source_fields(field) if isinstance(f, TimeSteppedField)]
        self.period_s = period_s
        self._next = 0.0
        self._times: queue.Queue[float] = queue.Queue(maxsize=4)

    @property
    def active(self) -> bool:
        return bool(self.sources) and self.period_s > 0.0

    def on_clock(self, sim_time_s: float) -> None:
        """Called with each clock; queues the latest due publication time."""
        if sim_time_s + 1e-9 < self._next and sim_time_s + self.period_s > self._next:
            return
        due = math.floor(sim_time_s / self.period_s + 1e-9) * self.period_s
        self._next = due + self.period_s
        with contextlib.suppress(queue.Full):
            self._times.put_nowait(due)

    def next_time(self, timeout_s: float) -> float | None:
        try:
            return self._times.get(timeout=timeout_s)
        except queue.Empty:
            return None

    def state(self, sim_time_s: float) -> PlumeState:
        centres, radii = [], []
        for source in self.sources:
            if isinstance(source, FilamentPlume):
                c, r = source.filaments(sim_time_s)
            elif isinstance(source, PuffPlume):
                c, r, _ = source.puffs(sim_time_s)
            else:
                continue
            centres.append(c)
            radii.append(r)
        c_all = np.concatenate(centres) if centres else np.empty((0, 3))
        r_all = np.concatenate(radii) if radii else np.empty(0)
        return PlumeState(
            sim_time_s=sim_time_s,
            model="+".join(sorted({_model_name(f) for f in self.sources})),
            count=int(r_all.shape[0]),
            centres_f32=np.asarray(c_all, dtype="<f4").tobytes(),
            radii_f32=np.asarray(r_all, dtype="<f4").tobytes(),
        )


class SensorAnswers:
    """The service's part of the lockstep: answers each sensor tick (``sim/sensor``) with a
    :class:`FieldSample` through ``put`` (see the module doc)."""

    def __init__(self, service: PlumeService, put: Callable[[bytes], object]) -> None:
        self.service = service
        self._put = put
        self._last: tuple[int, bytes] | None = None  # the last answer: tick, payload
        self._lock = threading.Lock()

    def on_tick(self, data: bytes) -> None:
        view = decode_or_none(data, TickView, "a sensor tick", log)
        if view is None:
            return
        with self._lock:
            last = self._last
            if last is None or last[0] != view.tick:
                last = self._last = (view.tick, self._answer(view))
        self._put(last[1])

    def _answer(self, view: TickView) -> bytes:
        try:
            points = [state_head_decoder.decode(raw).position_enu_m for raw in view.states]
            sample = self.service.sample(view.tick, view.sim_time_s, points)
        except (msgspec.DecodeError, ValueError) as exc:
            log.warning("plume: no values for tick %d: %s", view.tick, exc)
            sample = FieldSample(tick=view.tick, sim_time_s=view.sim_time_s, values_g_m3=None)
        return encode(sample)


def serve_queries(
    session: zenoh.Session, keys: Keys, service: PlumeService, stop: threading.Event
) -> tuple[list[zenoh.Queryable[None]], threading.Thread]:
    """The three queryables, and the thread that computes meshes until ``stop``.

    Meshes take seconds: they queue to their own thread so point queries never wait. (A
    blocking recv() on a zenoh channel can't be interrupted by undeclare; a Python queue with a
    timeout can.) Point queries are memoised: clients asking the same points at the same sim
    time (viewers, tools) share one computation."""
    mesh_queue: queue.Queue[Incoming[PlumeMeshQuery]] = queue.Queue(maxsize=8)

    def enqueue_mesh(incoming: Incoming[PlumeMeshQuery]) -> None:
        try:
            mesh_queue.put_nowait(incoming)
        except queue.Full:
            incoming.refuse("", "mesh queue full, retry later")

    def mesh_worker() -> None:
        while not stop.is_set():
            try:
                incoming = mesh_queue.get(timeout=0.2)
            except queue.Empty:
                continue
            incoming.answer(service.mesh)

    queryables = [
        serve(session, keys.plume_concentration(), PlumeQuery, service.concentration, memo=True),
        serve(session, keys.plume_info(), PlumeInfoQuery, service.info),
        serve_later(session, keys.plume_mesh(), PlumeMeshQuery, enqueue_mesh),
    ]
    worker = threading.Thread(target=mesh_worker, name="plume-mesh", daemon=True)
    worker.start()
    return queryables, worker


class PlumeOptions(RoleOptions, frozen=True, kw_only=True):
    """The plume role takes no options (everything is in the scenario): any ``--set`` is
    refused."""


def _start_state_publisher(
    rt: NodeRuntime, states: StatePublisher
) -> tuple[zenoh.Subscriber[None], threading.Thread]:
    """Publish the field's state on ``field/state`` at the sim times the clock reaches."""
    publisher = rt.session.declare_publisher(rt.keys.plume_state())

    def on_clock(sample: zenoh.Sample) -> None:
        data = payload_or_none(sample, "a clock message", log)
        key = str(sample.key_expr)
        clock = None if data is None else decode_or_none(data, Clock, "a clock message", log, key)
        if clock is None:
            return
        states.on_clock(clock.sim_time_s)

    def state_worker() -> None:
        while not rt.stop.is_set():
            t = states.next_time(0.2)
            if t is not None:
                publisher.put(encode(states.state(t)))

    subscriber = rt.session.declare_subscriber(rt.keys.clock(), on_clock)
    state_thread = threading.Thread(target=state_worker, name="plume-state", daemon=True)
    state_thread.start()
    return subscriber, state_thread


def _on_sensor_tick(answers: SensorAnswers, sample: zenoh.Sample) -> None:
    data = payload_or_none(sample, "a sensor tick", log)
    if data is not None:
        answers.on_tick(data)


@role_main(PlumeOptions, "plume")
def main(ctx: NodeContext, options: PlumeOptions) -> int:
    """Serve the scenario's plume until stopped."""
    del options  # none are declared: an unknown one is refused
    service = PlumeService(field_from_scenario(ctx.scenario), ctx.scenario)
    states = StatePublisher(service.field, ctx.scenario.plume.state_period_s)
    # One Zenoh thread: a sensor tick is received, sampled and answered with no hand-over
    # between threads (as the autopilot's ticks); an operator's own ZENOH_RUNTIME wins.
    os.environ.setdefault("ZENOH_RUNTIME", SINGLE_THREAD_RUNTIME)
    with NodeRuntime(ctx, role="plume", check_scenario_of="physics") as rt:
        queryables, mesh_worker = serve_queries(rt.session, rt.keys, service, rt.stop)
        sample_pub = rt.session.declare_publisher(rt.keys.plume_sample())
        answers = SensorAnswers(service, sample_pub.put)
        tick_sub = rt.session.declare_subscriber(
            rt.keys.sensor_tick(), lambda sample: _on_sensor_tick(answers, sample)
        )
        state_feed = _start_state_publisher(rt, states) if states.active else None
        rt.ready()
        rt.stop.wait()
        mesh_worker.join(timeout=30.0)
        if state_feed is not None:
            subscriber, state_thread = state_feed
            state_thread.join(timeout=30.0)
            subscriber.undeclare()
        tick_sub.undeclare()
        for q in queryables:
            q.undeclare()
        refused = rt.refusal is not None
    return 2 if refused else 0
