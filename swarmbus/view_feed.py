"""What every view of the world takes from the bus, free of any drawing library: the newest
tick and readings (:class:`Feed`), the plume's isosurfaces (``plume/mesh``, :class:`MeshFetcher`)
and the colours vehicles, readings and plume levels are drawn in. The meshcat viewer and the
Foxglove views share it.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import zenoh

from swarmbus.codec import decode_or_none
from swarmbus.keys import KeyNameError, Keys
from swarmbus.messages import ConcentrationReading, PlumeMesh, PlumeMeshQuery, PlumeState, SimTick
from swarmbus.reqrep import NoReply, RequestError, ask
from swarmbus.scenario import Scenario

log = logging.getLogger(__name__)

# Vehicle colours (Tableau 10), one per vehicle in scenario order.
PALETTE = (
    0x1F77B4,
    0xFF7F0E,
    0x2CA02C,
    0xD62728,
    0x9467BD,
    0x8C564B,
    0xE377C2,
    0x7F7F7F,
    0xBCBD22,
    0x17BECF,
)
PLUME_COLOURS = (0x6A3D9A, 0xE31A1C, 0xFFD92F)
MESH_RETRY_S = 2.0
READING_BINS = 16


def default_levels(scenario: Scenario) -> tuple[float, ...]:
    """The sensor window's edges and its middle (geometric), else a decade of levels."""
    sensor = scenario.sensor.resolved()
    low = sensor.detection_limit_g_m3 or 0.01
    high = sensor.saturation_g_m3 or low * 20.0
    return (low, math.sqrt(low * high), high)


def scene_bounds(
    scenario: Scenario,
) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """A box around sources, spawns and mission items (ENU m), padded."""
    pts = [(s.x_m, s.y_m, s.release_height_m) for s in scenario.plume.sources]
    for v in scenario.vehicles:
        pts.append(v.spawn_enu_m)
        pts += [(m.x, m.y, m.z) for m in v.mission if m.frame == "enu"]
    arr = np.array(pts, dtype=float)
    lo = arr.min(axis=0) - np.array([10.0, 15.0, 0.0])
    hi = arr.max(axis=0) + np.array([20.0, 15.0, 15.0])
    lo[2] = 0.0
    return (float(lo[0]), float(lo[1]), float(lo[2])), (float(hi[0]), float(hi[1]), float(hi[2]))


def reading_colour(value: float, full_scale: float) -> int:
    """Blue (nothing) → red (saturated), in ``READING_BINS`` steps."""
    t = 0.0 if full_scale <= 0 else min(1.0, max(0.0, value / full_scale))
    t = round(t * (READING_BINS - 1)) / (READING_BINS - 1)
    r, g, b = int(255 * t), int(80 * (1 - abs(2 * t - 1))), int(255 * (1 - t))
    return (r << 16) | (g << 8) | b


def plume_points(
    state: PlumeState,
) -> tuple[np.ndarray[Any, np.dtype[np.float64]], np.ndarray[Any, np.dtype[np.float64]]]:
    """A ``field/state``'s filament or puff centres (P, 3) and radii (P,). The bus is open: a
    torn or garbled payload that still decodes gives only its whole rows (as many as both
    arrays have), never an exception."""
    centres = _whole_f32(state.centres_f32, per_row=3).reshape(-1, 3)
    radii = _whole_f32(state.radii_f32)
    n = min(len(centres), len(radii))
    return centres[:n], radii[:n]


def _whole_f32(raw: bytes, per_row: int = 1) -> np.ndarray[Any, np.dtype[np.float64]]:
    whole = len(raw) // (4 * per_row) * 4 * per_row
    return np.frombuffer(raw[:whole], dtype="<f4").astype(np.float64)


class Feed:
    """Newest payloads from the bus; callbacks only store bytes."""

    def __init__(self, session: zenoh.Session, keys: Keys) -> None:
        self.keys = keys
        self._lock = threading.Lock()
        self._tick: bytes | None = None
        self._readings: dict[str, bytes] = {}
        self._plume_state: bytes | None = None
        self._subs = [
            session.declare_subscriber(keys.tick(), self._on_tick),
            session.declare_subscriber(keys.all_vehicle_concentration(), self._on_reading),
            session.declare_subscriber(keys.plume_state(), self._on_plume_state),
        ]

    def _on_plume_state(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self._plume_state = sample.payload.to_bytes()

    def take_plume_state(self) -> bytes | None:
        """The newest ``field/state`` payload (once)."""
        with self._lock:
            state, self._plume_state = self._plume_state, None
        return state

    def _on_tick(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self._tick = sample.payload.to_bytes()

    def _on_reading(self, sample: zenoh.Sample) -> None:
        try:
            vid = self.keys.vehicle_id_of(str(sample.key_expr))
        except KeyNameError:
            return
        with self._lock:
            self._readings[vid] = sample.payload.to_bytes()

    def take(self) -> tuple[bytes | None, dict[str, bytes]]:
        """The newest tick (once) and the newest readings (once each)."""
        with self._lock:
            tick, self._tick = self._tick, None
            readings, self._readings = self._readings, {}
        return tick, readings

    def take_decoded(self) -> Fresh:
        """:meth:`take`, then :meth:`take_plume_state`, decoded; a payload that does not decode
        is logged and left out."""
        tick_raw, readings_raw = self.take()
        tick = None if tick_raw is None else decode_or_none(tick_raw, SimTick, "tick", log)
        read = [
            decode_or_none(raw, ConcentrationReading, f"reading of {vid}", log)
            for vid, raw in readings_raw.items()
        ]
        state_raw = self.take_plume_state()
        state = (
            None if state_raw is None else decode_or_none(state_raw, PlumeState, "plume state", log)
        )
        return Fresh(tick, [r for r in read if r is not None], state)

    def close(self) -> None:
        for sub in self._subs:
            sub.undeclare()


@dataclass(frozen=True)
class Fresh:
    """What a view has not drawn yet: the newest tick, the newest reading of each vehicle that
    sent one, the newest plume state (each None or empty when nothing new came)."""

    tick: SimTick | None
    readings: list[ConcentrationReading]
    plume_state: PlumeState | None


def fetch_mesh(
    session: zenoh.Session, keys: Keys, query: PlumeMeshQuery, timeout_s: float = 10.0
) -> PlumeMesh | None:
    """One ``plume/mesh`` query; None when nobody answered or it failed (logged)."""
    outcome = ask(session, keys.plume_mesh(), query, PlumeMesh, timeout_s).outcome()
    if isinstance(outcome, NoReply):  # not there yet: asked again
        return None
    if isinstance(outcome, RequestError):
        log.warning("plume mesh: %s", outcome)
        return None
    return outcome


class MeshFetcher:
    """Asks ``plume/mesh`` for each level on its own thread until every level is answered."""

    def __init__(
        self, session: zenoh.Session, keys: Keys, queries: Sequence[PlumeMeshQuery]
    ) -> None:
        self.results: dict[int, PlumeMesh] = {}
        self.queries = list(queries)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(
            target=self._run, args=(session, keys, list(queries)), name="plume-mesh", daemon=True
        )
        self._thread.start()

    def _run(self, session: zenoh.Session, keys: Keys, queries: list[PlumeMeshQuery]) -> None:
        pending = dict(enumerate(queries))
        while pending and not self._stop.is_set():
            for i, q in list(pending.items()):
                mesh = fetch_mesh(session, keys, q)
                if mesh is not None:
                    with self._lock:
                        self.results[i] = mesh
                    del pending[i]
            self._stop.wait(MESH_RETRY_S)

    def take(self) -> dict[int, PlumeMesh]:
        with self._lock:
            out, self.results = self.results, {}
        return out

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=15.0)


def isosurface_queries(
    scenario: Scenario, levels_g_m3: Sequence[float] = (), resolution_m: float = 1.0
) -> list[PlumeMeshQuery]:
    """The ``plume/mesh`` queries of a view: ``levels_g_m3`` (default: :func:`default_levels`)
    over the box around the scenario (:func:`scene_bounds`). None for a time-dependent plume
    (filaments, puffs): it is drawn from its state (``field/state``) instead."""
    models = {src.model or scenario.plume.model for src in scenario.plume.sources}
    if models != {"gaussian"}:
        return []
    lo, hi = scene_bounds(scenario)
    levels = levels_g_m3 or default_levels(scenario)
    return [
        PlumeMeshQuery(
            level_g_m3=level,
            resolution_m=resolution_m,
            bounds_min_m=lo,
            bounds_max_m=hi,
        )
        for level in levels
    ]
