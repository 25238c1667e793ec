"""Cooperative gradient swarm: ≥ 3 vehicles estimate the concentration gradient together from
their own and their peers' readings and climb it in formation.

The scheme of Ögren, Fiorelli & Leonard (2004), "Cooperative control of mobile sensor
networks: adaptive gradient climbing in a distributed environment", IEEE TAC 49(8):1292, in its
simplest form: every member averages the swarm's readings (its own and each peer's, with their
positions) over ``window_s`` (2 s), fits a plane to ln(mean + ``window_floor_g_m3``) over the
members' means (least squares, :func:`log_gradient`; a single instantaneous reading of an
intermittent plume says nothing about the mean, and one zero would weigh ln 10⁻¹² = −27.6),
and the whole formation moves along the fitted gradient at ``climb_speed_m_s``. ln c turns
the Gaussian plume's crosswind profile into a parabola, so the fitted direction points toward
the plume's axis and up it to the source at any distance.

The readings: a vehicle's own reading carries its peers' positions and the field's values there
at the same sensor tick (``ConcentrationReading.peers``). The fit uses what each peer's sensor
reports, as a swarm sharing its readings would: every member passes each peer's field value
through a copy of that peer's sensor model (:class:`agents.sensor.ConcentrationSensor` with the
peer's index and seed — the same lag, noise and transducer, so the same bits the peer reports
for the samples it has seen since this member's first reading), so every member fits the same
kind of values (its own sensor output and its peers') and computes the same motion — no extra
messages. Formation: the members
(sorted by vehicle id) sit on a regular polygon of radius ``formation_radius_m`` around the
swarm's centroid, the first vertex upwind; each flies the common climb velocity plus a
proportional pull to its vertex.

When no member reads gas the swarm casts crosswind in formation (legs of growing width,
drifting downwind). Stopping rule: once it has found gas and its centroid has moved less than
``stall_m`` over the last ``stall_s`` (climbing has stopped: at the source the fitted
gradient flips back and forth), every member declares the source at the strongest reading
the swarm took. Wind: the wind input (:mod:`agents.behaviors.wind`).

Use ``behavior = "agents.behaviors.gradient_swarm:GradientSwarm"`` on every member.
"""

from __future__ import annotations

import math
import sys
from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import CrosswindSweep, fly
from agents.behaviors.wind import WindFrame
from agents.sensor import ConcentrationSensor
from swarmbus.messages import ConcentrationReading, PeerReading, Setpoint, VehicleState

#: Added to every reading before the logarithm (g/m³), so that a zero reading is finite.
LOG_FLOOR_G_M3 = 1e-12


def log_gradient(
    points_xy: npt.ArrayLike, values_g_m3: npt.ArrayLike, floor_g_m3: float = LOG_FLOOR_G_M3
) -> tuple[float, float]:
    """Least-squares gradient (per metre) of ln(c + floor) from ≥ 3 non-collinear readings.

    The plane's slopes in closed form, in correctly rounded float operations (``math.fsum``
    sums, one ``math.log`` per reading): the same bits whichever BLAS kernels the CPU selects.
    A LAPACK solver (``np.linalg.lstsq``) runs those kernels (AVX2, AVX-512, ...), whose last
    bits differ, and a swarm that climbs the fitted direction turns a last bit into another
    flight. Collinear readings (rank 2 of 3, as ``lstsq`` with its default cut-off
    decides it) give the least-norm slope, along their line; coincident ones give 0."""
    pts = np.asarray(points_xy, dtype=np.float64)
    if pts.shape[0] < 3:
        raise ValueError(f"need at least 3 readings for a gradient, got {pts.shape[0]}")
    xs = [float(v) for v in pts[:, 0]]
    ys = [float(v) for v in pts[:, 1]]
    logs = [math.log(float(v) + floor_g_m3) for v in np.asarray(values_g_m3, dtype=np.float64)]
    n = len(xs)
    mx, my, ml = math.fsum(xs) / n, math.fsum(ys) / n, math.fsum(logs) / n
    dx = [x - mx for x in xs]
    dy = [y - my for y in ys]
    dl = [v - ml for v in logs]
    sxx = math.fsum(a * a for a in dx)
    syy = math.fsum(b * b for b in dy)
    sxy = math.fsum(a * b for a, b in zip(dx, dy, strict=True))
    sxl = math.fsum(a * c for a, c in zip(dx, dl, strict=True))
    syl = math.fsum(b * c for b, c in zip(dy, dl, strict=True))
    # the eigenvalues of [[sxx, sxy], [sxy, syy]]: the squared singular values of the centred
    # positions (the column of ones, orthogonal to them, has sqrt(n))
    half, spread = 0.5 * (sxx + syy), math.hypot(0.5 * (sxx - syy), sxy)
    big = half + spread
    det = sxx * syy - sxy * sxy
    cut = (sys.float_info.epsilon * n) ** 2 * max(float(n), big)  # lstsq's rcond=None
    if big <= cut:
        return 0.0, 0.0
    if det <= cut * big:  # collinear: the least-norm slope, along the principal axis
        ux, uy = sxy, big - sxx
        if abs(big - syy) > abs(big - sxx):
            ux, uy = big - syy, sxy
        norm = math.hypot(ux, uy)
        ux, uy = ux / norm, uy / norm
        along = (ux * sxl + uy * syl) / big
        return along * ux, along * uy
    return (syy * sxl - sxy * syl) / det, (sxx * syl - sxy * sxl) / det


class GradientSwarm(SeekingBehavior):
    own_state = (
        "gradient",
        "best_g_m3",
        "best_xy",
        "centroids",
        "sweep",
        "peer_lags",
        "window",
        "window_start_s",
    )
    climb_speed_m_s = 2.0
    formation_radius_m = 2.0
    formation_gain = 1.0
    cast_speed_m_s = 2.0
    cast_drift_m_s = 0.5
    first_cast_half_width_m = 5.0
    cast_growth = 1.6
    stall_s = 10.0
    stall_m = 1.5
    window_s = 2.0
    window_floor_g_m3 = 1e-4

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.vehicle_id = ctx.vehicle_id
        self.scenario = ctx.scenario
        # each peer's sensor model, and its lag history (the state a checkpoint keeps)
        self.peer_sensors: dict[str, ConcentrationSensor] = {}
        self.peer_lags: dict[str, deque[tuple[float, float]]] = {}
        self.gradient: tuple[float, float] | None = None
        self.best_g_m3 = 0.0
        self.best_xy: tuple[float, float] | None = None
        self.centroids: deque[tuple[float, float, float]] = deque()
        self.window: dict[str, list[float]] = {}  # vehicle id: n, Σx, Σy, Σvalue
        self.window_start_s: float | None = None
        self.sweep = CrosswindSweep(
            self.cast_speed_m_s, self.cast_drift_m_s, self.first_cast_half_width_m, self.cast_growth
        )

    def _observe(self, readings: Sequence[ConcentrationReading]) -> None:
        for r in readings:
            if not r.available or r.reported_g_m3 is None:
                continue
            pts = [(r.position_enu_m[0], r.position_enu_m[1])]
            vals = [r.reported_g_m3]
            ids = [self.vehicle_id]
            for p in r.peers:
                pts.append((p.position_enu_m[0], p.position_enu_m[1]))
                vals.append(self.peer_output(p, r.sim_time_s))
                ids.append(p.vehicle_id)
            for vid, (x, y), v in zip(ids, pts, vals, strict=True):
                if v > self.best_g_m3:
                    self.best_g_m3, self.best_xy = v, (x, y)
                acc = self.window.setdefault(vid, [0.0, 0.0, 0.0, 0.0])  # n, Σx, Σy, Σvalue
                acc[0] += 1.0
                acc[1] += x
                acc[2] += y
                acc[3] += v
            if self.window_start_s is None:
                self.window_start_s = r.sim_time_s
            if r.sim_time_s - self.window_start_s >= self.window_s:
                self._fit()

    def _fit(self) -> None:
        """The gradient of ln(mean + floor) over each member's mean reading and position in
        the window; then a new window."""
        means = [(sx / n, sy / n, sv / n) for n, sx, sy, sv in self.window.values() if n > 0]
        self.window = {}
        self.window_start_s = None
        vals = [v for _, _, v in means]
        if len(means) >= 3 and max(vals) > 0.0:
            pts = [(x, y) for x, y, _ in means]
            self.gradient = log_gradient(pts, vals, self.window_floor_g_m3)
        elif max(vals, default=0.0) <= 0.0:
            self.gradient = None

    def restore(self, data: dict[str, Any]) -> None:
        super().restore(data)
        self.peer_sensors = {}  # rebuilt from peer_lags on the next reading

    def peer_output(self, peer: PeerReading, sim_time_s: float) -> float:
        """What ``peer``'s sensor reports for its field value at ``sim_time_s``."""
        sensor = self.peer_sensors.get(peer.vehicle_id)
        if sensor is None:
            index = [v.id for v in self.scenario.vehicles].index(peer.vehicle_id)
            sensor = ConcentrationSensor.for_vehicle(self.scenario, index)
            sensor.resume(self.peer_lags.get(peer.vehicle_id, ()))
            self.peer_sensors[peer.vehicle_id] = sensor
            self.peer_lags[peer.vehicle_id] = sensor.lag_history
        return sensor.sample(peer.true_g_m3, sim_time_s)

    def _stalled(self, now: float, cx: float, cy: float) -> bool:
        self.centroids.append((now, cx, cy))
        while self.centroids and now - self.centroids[0][0] > self.stall_s:
            self.centroids.popleft()
        t0, x0, y0 = self.centroids[0]
        return now - t0 >= 0.95 * self.stall_s and math.hypot(cx - x0, cy - y0) < self.stall_m

    def _slot(self, own: VehicleState, peers: Sequence[VehicleState]) -> int:
        ids = sorted([own.vehicle_id, *(p.vehicle_id for p in peers)])
        return ids.index(own.vehicle_id)

    def seek(self, step: SeekStep) -> Setpoint | None:
        own, peers, wind = step.own, step.peers, step.wind
        x, y, _ = own.position_enu_m
        frame = wind.frame
        self._observe(step.readings)
        members = [own, *peers]
        cx = sum(m.position_enu_m[0] for m in members) / len(members)
        cy = sum(m.position_enu_m[1] for m in members) / len(members)
        if self.best_xy is not None and self._stalled(own.sim_time_s, cx, cy):
            bx, by = self.best_xy
            self.declaration = SourceEstimate(x_m=bx, y_m=by, sim_time_s=own.sim_time_s)
            return None
        climb = self._climb_velocity(frame, cx, cy)
        n = len(members)
        angle = 2.0 * math.pi * self._slot(own, peers) / n
        # First vertex upwind; the others around the polygon.
        off_along = -self.formation_radius_m * math.cos(angle)
        off_across = self.formation_radius_m * math.sin(angle)
        ox, oy = frame.velocity(off_along, off_across)  # a displacement, in the same frame
        k = self.formation_gain
        vx = climb[0] + k * (cx + ox - x)
        vy = climb[1] + k * (cy + oy - y)
        return fly(own, (vx, vy), self.altitude)

    def _climb_velocity(self, frame: WindFrame, cx: float, cy: float) -> tuple[float, float]:
        if self.gradient is not None:
            gx, gy = self.gradient
            norm = math.hypot(gx, gy)
            if norm > 0.0:
                self.sweep.restart()
                return self.climb_speed_m_s * gx / norm, self.climb_speed_m_s * gy / norm
        return self.sweep.velocity(frame, cx, cy)
