"""Tracking an intermittent plume upwind, and declaring its source on evidence.

The common core of casting and surge-cast (:class:`PlumeTracker`, and the behaviour around it,
:class:`TrackingBehavior`), built for the signal a
searcher meets in a real plume: short whiffs separated by blanks, the plume's centreline
wandering with the wind.

* **Hit memory** (``memory_s``): the searcher keeps surging through blanks shorter than this.
  It is set above the blanks a searcher meets on the plume's axis, so that a blank between two
  filaments is not taken for the plume's edge: 2.0 s, above the 90th percentile (0.6–1.3 s)
  and within the 99th (1.6–2.9 s) of ``meander_low``'s blank durations at a fixed point on the
  axis, and above the 90th percentile of ``meander_high``'s (0.8–1.5 s) (30, 50, 80 m
  downwind at the flight altitude, 10 Hz, threshold 0.001 g/m³, 600 s,
  ``swarmbus/scenarios/gsl/statistics.json``, docs/plume.md). Longer blanks — ``meander_high``'s
  99th percentile is 8.6–11.2 s — are the plume swinging away: for casting.
* **Averaged wind** (``wind_average_s``): surging and casting steer in the frame of the wind
  averaged (exponentially, time constant 3 s) over the last seconds, not the instantaneous
  anemometer reading; a cast keeps the frame of the averaged wind at the last hit.
* **Casting without drift**: after a loss the searcher flies straight downwind (along the
  mean wind) back to the *cast line*, ``line_ahead_m`` (1.5 m) upwind of the *frontier* — the
  most upwind detection so far, along the wind averaged over the whole search — and casts
  crosswind along it with legs of growing width, without drifting. A hit starts a new surge.
* **Declaration by evidence**: the cast along the line is *empty* once it has flown
  ``empty_legs`` legs (8, half-widths growing to the behaviour's cap of 20 m, wider than the
  plume's swing near the frontier: a crossing of the filament thread at 2.5 m/s takes ≈ 3
  samples at 10 Hz, each a hit with ≥ 22 % (the lowest axis hit fraction of the calibrated
  filament environments, ``meander_high`` at 80 m; ``meander_low``: 24–42 %), so a crossing
  misses with ≤ 0.48 and eight with ≤ 0.3 %; in the tuning, on Farrell's meander-free thread
  (the ``lab_thread`` parameters), five legs declared falsely in 3 of 10 runs of casting),
  lasted ``blank_factor`` (1.5) times the longest
  blank the searcher has met between two of its own detections (an online statistic of the
  blank-duration distribution, so that a searcher in a strongly meandering plume waits
  longer), and the search has made ``min_hits``
  (10) detections. The source then lies between the frontier and the line: it is declared at
  their midpoint along the mean wind (error ≤ 0.75 m along the wind if the source is in that
  interval); crosswind, the median of the detections within ``cluster_m`` (3 m) of the
  frontier. A first whiff or a strong filament is never a declaration.
* **Search in height** (``vertical_step_m``, off at 0, the published tables' setting): the
  surge flies at the altitude of the last detection, and each leg of a sweep at another
  offset from it (0, +1, −1, +2, … steps, within ``max_vertical_offset_m`` of the altitude the
  search started at, never below ``min_flight_altitude_m``), so that a release above or below
  that altitude is followed up to its height; at a fixed altitude the frontier stops where
  the plume first reaches that height, metres downwind of such a release.
  ``max_search_half_width_m`` (0: the cast's cap) widens the sweep before the first
  detection, for a start beside the plume. docs/gsl.md has their tuning measurement.
"""

from __future__ import annotations

import math
import statistics
from abc import abstractmethod
from collections.abc import Sequence
from dataclasses import InitVar, dataclass, field
from typing import ClassVar

from agents.behavior import BehaviorContext, SourceEstimate
from agents.behavior_state import SavesState
from agents.behaviors.detection import PLUME_THRESHOLD_G_M3, detector_for
from agents.behaviors.seeking import SeekingBehavior, SeekStep
from agents.behaviors.steering import CrosswindSweep, fly
from agents.behaviors.wind import WindFrame
from swarmbus.messages import ConcentrationReading, Setpoint


class AveragedWind(SavesState):
    """Exponential moving average of the wind vector (time constant ``time_constant_s``) and
    the plain mean of every reading (the mean wind of the search)."""

    state_attributes = ("average", "last_s", "total", "count")

    def __init__(self, time_constant_s: float) -> None:
        self.time_constant_s = time_constant_s
        self.average: tuple[float, float] | None = None
        self.last_s: float | None = None
        self.total = (0.0, 0.0)
        self.count = 0

    def add(self, wind_m_s: tuple[float, float], sim_time_s: float) -> None:
        self.total = (self.total[0] + wind_m_s[0], self.total[1] + wind_m_s[1])
        self.count += 1
        if self.average is None or self.last_s is None:
            self.average = wind_m_s
        else:
            dt = max(sim_time_s - self.last_s, 0.0)
            a = -math.expm1(-dt / self.time_constant_s) if self.time_constant_s > 0.0 else 1.0
            self.average = (
                self.average[0] + a * (wind_m_s[0] - self.average[0]),
                self.average[1] + a * (wind_m_s[1] - self.average[1]),
            )
        self.last_s = sim_time_s

    def recent(self) -> WindFrame:
        assert self.average is not None
        return WindFrame.of(self.average)

    def mean(self) -> WindFrame:
        n = max(self.count, 1)
        return WindFrame.of((self.total[0] / n, self.total[1] / n))


@dataclass(eq=False)
class PlumeTracker(SavesState):
    """The surge / cast state machine and the evidence declaration.

    States: ``search`` (no hit yet: crosswind sweep), ``surge`` (a hit within ``memory_s``),
    ``cast`` (casting where the plume was lost). Call :meth:`observe_wind` and :meth:`hit`
    (for every detection), then :meth:`advance` and :meth:`velocity` once per control step; the
    behaviour decides how to surge.
    """

    state_attributes: ClassVar[tuple[str, ...]] = (
        "state",
        "last_hit_s",
        "longest_blank_s",
        "hits",
        "wind",
        "cast_frame",
        "cast",
        "cast_line",
    )

    cast: CrosswindSweep  # the cast's legs (no drift), also the search before the first hit
    memory_s: float = 2.0
    wind_average_s: InitVar[float] = 3.0
    empty_legs: int = 8
    min_hits: int = 10
    cluster_m: float = 3.0
    line_ahead_m: float = 1.5
    back_speed_m_s: float = 2.0
    blank_factor: float = 1.5
    search_half_width_m: float = 0.0  # the sweep's cap before the first hit; 0: the cast's
    state: str = field(default="search", init=False)
    last_hit_s: float | None = field(default=None, init=False)
    longest_blank_s: float = field(default=0.0, init=False)
    hits: list[tuple[float, float]] = field(default_factory=list, init=False)  # ENU positions
    wind: AveragedWind = field(init=False)
    cast_frame: tuple[float, float] | None = field(default=None, init=False)  # wind at last hit
    cast_line: tuple[int, float] | None = field(default=None, init=False)  # legs before, along m

    def __post_init__(self, wind_average_s: float) -> None:
        self.wind = AveragedWind(wind_average_s)

    def observe_wind(self, wind_m_s: tuple[float, float], sim_time_s: float) -> None:
        self.wind.add(wind_m_s, sim_time_s)

    def hit(self, x_m: float, y_m: float, sim_time_s: float) -> None:
        if self.last_hit_s is not None:
            self.longest_blank_s = max(self.longest_blank_s, sim_time_s - self.last_hit_s)
        self.last_hit_s = sim_time_s
        self.hits.append((x_m, y_m))
        self.cast_frame = self.wind.average

    def frontier(self) -> tuple[float, float] | None:
        """(along, across) of the most upwind hit in the mean wind's frame; across: the median
        of the hits within ``cluster_m`` (along) of it."""
        if not self.hits:
            return None
        frame = self.wind.mean()
        coords = [frame.coordinates(x, y) for x, y in self.hits]
        along = min(a for a, _ in coords)
        across = statistics.median(c for a, c in coords if a - along <= self.cluster_m)
        return along, across

    def surging(self, now_s: float) -> bool:
        return self.last_hit_s is not None and now_s - self.last_hit_s <= self.memory_s

    def advance(self, x_m: float, y_m: float, now_s: float) -> SourceEstimate | None:
        """Advance the state machine; the declaration when the evidence is in."""
        if self.surging(now_s):
            self.state = "surge"
            return None
        if self.state == "surge":  # just lost: back to the line just upwind of the frontier
            front = self.frontier()
            assert front is not None
            self.state = "back"
            self.cast_line = (self.cast.legs, front[0] - self.line_ahead_m)
        if self.state == "back" and self.cast_line is not None:
            along, _ = self.wind.mean().coordinates(x_m, y_m)
            if along >= self.cast_line[1]:  # on the line: cast along it
                self.state = "cast"
                self.cast.restart()
                self.cast_line = (self.cast.legs, self.cast_line[1])
        elif self.state == "cast" and self.cast_line is not None and self._empty(now_s):
            return self._declare(self.cast_line[1], now_s)
        return None

    def _empty(self, now_s: float) -> bool:
        """The cast on the line has flown ``empty_legs`` legs and lasted ``blank_factor`` times
        the longest blank met so far, after ``min_hits`` detections."""
        assert self.cast_line is not None and self.last_hit_s is not None
        legs = self.cast.legs - self.cast_line[0]
        blank = now_s - self.last_hit_s
        return (
            legs >= self.empty_legs
            and blank >= self.blank_factor * self.longest_blank_s
            and len(self.hits) >= self.min_hits
        )

    def _declare(self, cast_line_m: float, now_s: float) -> SourceEstimate:
        """The source between the frontier and the empty cast line: their midpoint."""
        front = self.frontier()
        assert front is not None
        along = 0.5 * (front[0] + min(cast_line_m, front[0]))
        x, y = self.wind.mean().velocity(along, front[1])  # a point: the same linear map
        return SourceEstimate(x_m=x, y_m=y, sim_time_s=now_s)

    def velocity(self, x_m: float, y_m: float) -> tuple[float, float] | None:
        """The velocity of the search and cast states (None while surging)."""
        if self.state == "surge":
            return None
        if self.state == "back":  # straight downwind to the line
            return self.wind.mean().velocity(self.back_speed_m_s, 0.0)
        if self.state == "search" or self.cast_frame is None:
            frame = self.wind.recent()
        else:
            frame = WindFrame.of(self.cast_frame)
        searching = self.state == "search" and self.search_half_width_m > 0.0
        return self.cast.velocity(frame, x_m, y_m, self.search_half_width_m if searching else None)


class TrackingBehavior(SeekingBehavior):
    """A behaviour that flies a :class:`PlumeTracker`: each step it gives the tracker the wind
    and its detections (:meth:`observe`), advances it, and flies its search, back and cast
    velocities; while surging it flies upwind at ``surge_speed_m_s`` in the frame of the
    recent wind, ``surge_across_m_s()`` across it. The first sweep starts to the left on an
    even vehicle index, to the right on an odd one."""

    own_state: ClassVar[tuple[str, ...]] = ("detector", "tracker", "track_altitude_m")
    # the algorithm's numbers, given by each subclass
    surge_speed_m_s: float
    cast_speed_m_s: float
    first_cast_half_width_m: float
    cast_growth: float
    max_cast_half_width_m: float
    threshold_g_m3 = PLUME_THRESHOLD_G_M3
    # the search in height: 0 holds the altitude the search starts at
    vertical_step_m = 0.0
    max_vertical_offset_m = 5.0
    min_flight_altitude_m = 1.0  # never lower, whatever the offset (a search started low)
    # the sweep before the first detection: 0 grows it to the cast's cap
    max_search_half_width_m = 0.0
    # the sweep's crosswind coordinate from the point it began, so that the wind's frame
    # turning does not move the sweep (from the ENU origin: it moves by distance × angle)
    sweep_about_anchor = False

    def __init__(self, ctx: BehaviorContext) -> None:
        super().__init__(ctx)
        self.detector = detector_for(ctx, self.threshold_g_m3)
        cast = CrosswindSweep(
            self.cast_speed_m_s,
            0.0,
            self.first_cast_half_width_m,
            self.cast_growth,
            self.max_cast_half_width_m,
            side=1.0 if ctx.vehicle_index % 2 == 0 else -1.0,
            about_anchor=self.sweep_about_anchor,
        )
        self.tracker = PlumeTracker(cast, search_half_width_m=self.max_search_half_width_m)
        # the search in height: how many steps up (and down) its legs go
        self.vertical_steps = (
            max(1, int(self.max_vertical_offset_m / self.vertical_step_m))
            if self.vertical_step_m > 0.0
            else 0
        )
        self.track_altitude_m: float | None = None  # the altitude of the last detection

    def observe(self, readings: Sequence[ConcentrationReading]) -> None:
        """Give the tracker every detection among ``readings``."""
        for r in readings:
            if r.available and r.reported_g_m3 is not None and self.detector.hit(r.reported_g_m3):
                self.record(r)

    def record(self, reading: ConcentrationReading) -> None:
        """A detection: to the tracker, and its altitude is the one the search goes on at."""
        x, y, z = reading.position_enu_m
        self.tracker.hit(x, y, reading.sim_time_s)
        self.track_altitude_m = z

    def flight_altitude(self) -> float:
        """The altitude of this step. With ``vertical_step_m`` 0: the search's. Otherwise the
        surge flies at the altitude of the last detection, and each leg of a sweep (the
        search's and the cast's) at another offset from it — 0, +1, −1, +2, −2, … steps, as
        far as ``max_vertical_offset_m`` from the search's altitude and never below
        ``min_flight_altitude_m`` — so that a plume released above or below the search's
        altitude is followed to its height."""
        if self.vertical_step_m <= 0.0:
            return self.altitude
        tracker = self.tracker
        base = self.altitude if self.track_altitude_m is None else self.track_altitude_m
        if tracker.state not in ("search", "cast"):
            return base
        legs = tracker.cast.legs
        if tracker.state == "cast" and tracker.cast_line is not None:
            legs -= tracker.cast_line[0]
        m = legs % (2 * self.vertical_steps + 1)
        offset = (m + 1) // 2 * (1 if m % 2 else -1) * self.vertical_step_m
        low = max(self.altitude - self.max_vertical_offset_m, self.min_flight_altitude_m)
        return min(max(base + offset, low), self.altitude + self.max_vertical_offset_m)

    @abstractmethod
    def surge_across_m_s(self) -> float:
        """The cross-wind speed while surging."""

    def seek(self, step: SeekStep) -> Setpoint | None:
        own = step.own
        x, y, _ = own.position_enu_m
        tracker = self.tracker
        tracker.observe_wind(step.wind.vector_m_s, own.sim_time_s)
        self.observe(step.readings)
        self.declaration = tracker.advance(x, y, own.sim_time_s)
        velocity = tracker.velocity(x, y)
        if velocity is None:  # surging
            frame = tracker.wind.recent()
            velocity = frame.velocity(-self.surge_speed_m_s, self.surge_across_m_s())
        return fly(own, velocity, self.flight_altitude())
