"""Bus messages in, Foxglove messages out: the one conversion the recorder, ``plumeswarm export
foxglove`` and the live ``foxglove`` role share.

:class:`FoxgloveScene` is fed the typed bus messages a recording holds (in the order received,
with their receive time) and returns what to write on the Foxglove channels. Messages are
Foxglove's well-known schemas from the foxglove SDK (protobuf), except the concentration series,
a JSON channel per vehicle described by the JSON Schema of :class:`ConcentrationSample`.

Time: every Foxglove message is stamped with **simulation time**, anchored once to the wall clock
(the receive time of the first message that carries a sim time, minus that sim time), so that
Foxglove's timeline scrubs the simulation and stays next to the recording's raw channels (whose
log time is the receive time). Rates are counted in simulation time, so a run's Foxglove
channels are the same whether it was converted live or afterwards.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from foxglove import messages as fm

from recorder.foxglove.channels import (
    DEFAULT_VEHICLE_TYPE,
    LOCATION_PERIOD_S,
    NO_READING_RGB,
    PLUME_STATE_PERIOD_S,
    PLUME_STATE_TOPIC,
    PLUME_TOPIC,
    READINGS_PERIOD_S,
    READINGS_TOPIC,
    RESTART_S,
    SERIES_PERIOD_S,
    TF_PERIOD_S,
    TF_TOPIC,
    TRAIL_MAX_POINTS,
    TRAIL_POINT_PERIOD_S,
    TRAILS_PERIOD_S,
    TRAILS_TOPIC,
    VEHICLES_TOPIC,
    WORLD_FRAME,
    ConcentrationSample,
    Every,
    Out,
    colour,
    concentration_topic,
    heading_rad,
    location_topic,
    pose,
    stamp,
)
from recorder.foxglove.entities import (
    body_entity,
    isosurface_entity,
    plume_state_update,
    vehicle_type,
)
from swarmbus.messages import (
    ConcentrationReading,
    PlumeMesh,
    PlumeState,
    SimTick,
    VehicleState,
)
from swarmbus.scenario import Scenario
from swarmbus.view_feed import (
    PALETTE,
    default_levels,
    reading_colour,
)


@dataclass
class _Vehicle:
    index: int
    type_name: str
    state: VehicleState | None = None
    reading: ConcentrationReading | None = None
    trail: list[tuple[float, float, float, int]] = field(default_factory=list)  # x, y, z, rgb
    series_every: Every = field(default_factory=lambda: Every(SERIES_PERIOD_S))

    @property
    def rgb(self) -> int:
        return PALETTE[self.index % len(PALETTE)]


class FoxgloveScene:
    """The conversion, with the state it needs (newest state and reading per vehicle, trails,
    the plume). Feed it every bus message in order with :meth:`feed`."""

    def __init__(self, scenario: Scenario | None) -> None:
        self.scenario = scenario
        self._vehicles: dict[str, _Vehicle] = {}
        self._anchor_ns: int | None = None
        self._now_s = 0.0
        self._tf = Every(TF_PERIOD_S)
        self._readings = Every(READINGS_PERIOD_S)
        self._trails = Every(TRAILS_PERIOD_S)
        self._trail_points = Every(TRAIL_POINT_PERIOD_S)
        self._locations = Every(LOCATION_PERIOD_S)
        self._has_state = False
        self._plume_meshes: dict[float, PlumeMesh] = {}
        self._plume_pending = False
        self._plume_state: PlumeState | None = None
        self._plume_states = Every(PLUME_STATE_PERIOD_S)
        self._vehicles_pending = False
        self.full_scale_g_m3 = 1.0
        if scenario is not None:
            sensor = scenario.sensor.resolved()
            self.full_scale_g_m3 = sensor.saturation_g_m3 or max(default_levels(scenario))
            for v in scenario.vehicles:
                self._vehicle(v.id, v.type)

    @property
    def vehicle_ids(self) -> list[str]:
        """The vehicles of the scenario, then those seen on the bus, in order."""
        return list(self._vehicles)

    # ------------------------------------------------------------------ input
    def feed(self, message: object, log_time_ns: int) -> list[Out]:
        """The Foxglove messages due after ``message`` (received at ``log_time_ns``)."""
        handler = _HANDLERS.get(type(message))
        if handler is None:
            return []
        out: list[Out] = handler(self, message, log_time_ns)
        return out

    def _on_tick(self, tick: SimTick, log_time_ns: int) -> list[Out]:
        for st in tick.states:
            self._vehicle(st.vehicle_id).state = st
        self._has_state = self._has_state or bool(tick.states)
        return self._advance(tick.sim_time_s, log_time_ns)

    def _on_state(self, state: VehicleState, log_time_ns: int) -> list[Out]:
        self._vehicle(state.vehicle_id).state = state
        self._has_state = True
        return self._advance(state.sim_time_s, log_time_ns)

    def _on_reading(self, reading: ConcentrationReading, log_time_ns: int) -> list[Out]:
        v = self._vehicle(reading.vehicle_id)
        v.reading = reading
        # A reading is published once the plume answered, which in a lockstep faster than real
        # time is many ticks later: only the world's states move the clock.
        clock_s = reading.sim_time_s if self._anchor_ns is None else None
        out = self._advance(clock_s, log_time_ns)
        if v.series_every.due(reading.sim_time_s):
            x, y, z = reading.position_enu_m
            sample = ConcentrationSample(
                vehicle_id=reading.vehicle_id,
                sim_time_s=reading.sim_time_s,
                available=reading.available,
                reported_g_m3=reading.reported_g_m3,
                true_g_m3=reading.true_g_m3,
                x_m=x,
                y_m=y,
                z_m=z,
            )
            out.append(Out(concentration_topic(reading.vehicle_id), sample, self._ns(reading)))
        return out

    def _on_mesh(self, mesh: PlumeMesh, log_time_ns: int) -> list[Out]:
        self._plume_meshes[mesh.level_g_m3] = mesh
        self._plume_pending = True
        return self._advance(None, log_time_ns)

    def _on_plume_state(self, state: PlumeState, log_time_ns: int) -> list[Out]:
        # Stamped with its own sim time; like a reading, it moves the clock only to anchor it.
        clock_s = state.sim_time_s if self._anchor_ns is None else None
        out = self._advance(clock_s, log_time_ns)
        if self._anchor_ns is not None and self._plume_states.due(state.sim_time_s):
            self._plume_state = state
            out.append(self._plume_state_out(state))
        return out

    # ------------------------------------------------------------------ time
    def _ns(self, message: ConcentrationReading | PlumeState) -> int:
        assert self._anchor_ns is not None
        return self._anchor_ns + round(message.sim_time_s * 1e9)

    def _advance(self, t_s: float | None, log_time_ns: int) -> list[Out]:
        if t_s is not None:
            t_s = self._move_clock(t_s, log_time_ns)
            if t_s is None and not (self._vehicles_pending or self._plume_pending):
                return []
        if self._anchor_ns is None:
            return []  # nothing to stamp with yet: kept until the first sim time
        now_ns = self._anchor_ns + round(self._now_s * 1e9)
        out: list[Out] = []
        if self._vehicles_pending:
            out.append(Out(VEHICLES_TOPIC, self.vehicles_update(now_ns), now_ns))
        if self._plume_pending:
            out.append(Out(PLUME_TOPIC, self.plume_update(now_ns), now_ns))
        if t_s is not None:
            out += self._periodic(t_s, now_ns)
        return out

    def _move_clock(self, t_s: float, log_time_ns: int) -> float | None:
        """Sim time ``t_s`` made the scene's now (the first one anchors the log time); None when
        it is not later than what is drawn (a tick's states once more, one by one)."""
        if self._anchor_ns is None:
            self._anchor_ns = log_time_ns - round(t_s * 1e9)
        elif self._now_s - RESTART_S < t_s <= self._now_s:
            return None
        self._now_s = t_s
        return t_s

    def _periodic(self, t_s: float, now_ns: int) -> list[Out]:
        """Scene-wide periods: nothing is done per vehicle on a tick where nothing is due."""
        out: list[Out] = []
        if self._trail_points.due(t_s):
            self._sample_trails()
        if self._has_state and self._tf.due(t_s):
            out.append(Out(TF_TOPIC, self.transforms(now_ns), now_ns))
        if self._locations.due(t_s):
            out += self._locations_out(now_ns)
        if self._readings.due(t_s):
            update = self.readings_update(now_ns)
            if update is not None:
                out.append(Out(READINGS_TOPIC, update, now_ns))
        if self._trails.due(t_s):
            trails = self.trails_update(now_ns)
            if trails is not None:
                out.append(Out(TRAILS_TOPIC, trails, now_ns))
        return out

    def _locations_out(self, now_ns: int) -> list[Out]:
        return [
            Out(location_topic(vid), self.location(v, v.state, now_ns), now_ns)
            for vid, v in self._vehicles.items()
            if v.state is not None
        ]

    def static_messages(self) -> list[Out]:
        """The vehicles' bodies and the plume again (for a live client that joined late)."""
        if self._anchor_ns is None:
            return []
        now_ns = self._anchor_ns + round(self._now_s * 1e9)
        out = [
            Out(VEHICLES_TOPIC, self.vehicles_update(now_ns), now_ns),
            Out(PLUME_TOPIC, self.plume_update(now_ns), now_ns),
        ]
        if self._plume_state is not None:
            out.append(self._plume_state_out(self._plume_state))
        return out

    # ------------------------------------------------------------------ vehicles
    def _vehicle(self, vid: str, type_name: str = DEFAULT_VEHICLE_TYPE) -> _Vehicle:
        v = self._vehicles.get(vid)
        if v is None:
            v = self._vehicles[vid] = _Vehicle(index=len(self._vehicles), type_name=type_name)
            self._vehicles_pending = True
        return v

    def _sample_trails(self) -> None:
        for v in self._vehicles.values():
            st = v.state
            if st is None:
                continue
            v.trail.append((*st.position_enu_m, self._reading_rgb(v.reading)))
            del v.trail[:-TRAIL_MAX_POINTS]

    def _reading_rgb(self, reading: ConcentrationReading | None) -> int:
        if reading is None or reading.reported_g_m3 is None:
            return NO_READING_RGB
        return reading_colour(reading.reported_g_m3, self.full_scale_g_m3)

    def transforms(self, now_ns: int) -> fm.FrameTransforms:
        ts = stamp(now_ns)
        out = []
        for vid, v in self._vehicles.items():
            if v.state is None:
                continue
            (x, y, z), (qx, qy, qz, qw) = v.state.position_enu_m, v.state.attitude_xyzw
            out.append(
                fm.FrameTransform(
                    timestamp=ts,
                    parent_frame_id=WORLD_FRAME,
                    child_frame_id=vid,
                    translation=fm.Vector3(x=x, y=y, z=z),
                    rotation=fm.Quaternion(x=qx, y=qy, z=qz, w=qw),
                )
            )
        return fm.FrameTransforms(transforms=out)

    def location(self, v: _Vehicle, st: VehicleState, now_ns: int) -> fm.LocationFix:
        vx, vy, vz = st.velocity_enu_m_s
        return fm.LocationFix(
            timestamp=stamp(now_ns),
            frame_id=st.vehicle_id,
            latitude=st.lat_deg,
            longitude=st.lon_deg,
            altitude=st.alt_m,
            heading=heading_rad(st.attitude_xyzw),
            velocity=fm.Vector3(x=vx, y=vy, z=vz),
            color=colour(v.rgb),
        )

    def vehicles_update(self, now_ns: int) -> fm.SceneUpdate:
        """Each vehicle's body, rotors and name in its own frame (follows ``/tf``)."""
        self._vehicles_pending = False
        ts = stamp(now_ns)
        return fm.SceneUpdate(
            entities=[
                body_entity(vid, vehicle_type(v.type_name), v.rgb, ts)
                for vid, v in self._vehicles.items()
            ]
        )

    def readings_update(self, now_ns: int) -> fm.SceneUpdate | None:
        """A sphere above each vehicle at its newest reading, coloured and sized by it."""
        ts = stamp(now_ns)
        entities = []
        for vid, v in self._vehicles.items():
            r = v.reading
            if r is None:
                continue
            value = r.reported_g_m3
            t = 0.0 if value is None else min(1.0, value / self.full_scale_g_m3)
            radius = 0.3 + 1.2 * t
            x, y, z = v.state.position_enu_m if v.state is not None else r.position_enu_m
            label = "no reading" if value is None else f"{value:.3g} g/m³"
            entities.append(
                fm.SceneEntity(
                    timestamp=ts,
                    frame_id=WORLD_FRAME,
                    id=f"reading/{vid}",
                    spheres=[
                        fm.SpherePrimitive(
                            pose=pose(x, y, z + 1.5 + radius),
                            size=fm.Vector3(x=2 * radius, y=2 * radius, z=2 * radius),
                            color=colour(self._reading_rgb(r)),
                        )
                    ],
                    texts=[
                        fm.TextPrimitive(
                            pose=pose(x, y, z + 2.0 + 2 * radius),
                            billboard=True,
                            font_size=14.0,
                            scale_invariant=True,
                            color=colour(0xFFFFFF),
                            text=label,
                        )
                    ],
                )
            )
        return fm.SceneUpdate(entities=entities) if entities else None

    def trails_update(self, now_ns: int) -> fm.SceneUpdate | None:
        """Each vehicle's path, coloured by the concentration it read there (grey: none)."""
        ts = stamp(now_ns)
        entities = []
        for vid, v in self._vehicles.items():
            if len(v.trail) < 2:
                continue
            line = fm.LinePrimitive(
                type=fm.LinePrimitiveLineType.LineStrip,
                pose=pose(),
                thickness=3.0,
                scale_invariant=True,
                points=[fm.Point3(x=x, y=y, z=z) for x, y, z, _ in v.trail],
                colors=[colour(rgb) for *_, rgb in v.trail],
            )
            entities.append(
                fm.SceneEntity(timestamp=ts, frame_id=WORLD_FRAME, id=f"trail/{vid}", lines=[line])
            )
        return fm.SceneUpdate(entities=entities) if entities else None

    # ------------------------------------------------------------------ plume
    def plume_update(self, now_ns: int) -> fm.SceneUpdate:
        """The plume: its sources and what is known of its shape — the isosurfaces of the
        Gaussian plume (``plume/mesh`` replies), one translucent surface per level (a filament
        or puff plume's state is drawn on ``PLUME_STATE_TOPIC``, :func:`plume_state_update`)."""
        self._plume_pending = False
        ts = stamp(now_ns)
        entities = list(self._source_entities(ts))
        for i, (level, mesh) in enumerate(sorted(self._plume_meshes.items())):
            entity = isosurface_entity(i, level, mesh, ts)
            if entity is not None:
                entities.append(entity)
        return fm.SceneUpdate(entities=entities)

    def _plume_state_out(self, state: PlumeState) -> Out:
        ns = self._ns(state)
        return Out(PLUME_STATE_TOPIC, plume_state_update(state, ns), ns)

    def _source_entities(self, ts: fm.Timestamp) -> Iterable[fm.SceneEntity]:
        if self.scenario is None:
            return
        for i, src in enumerate(self.scenario.plume.sources):
            h = max(src.release_height_m, 0.1)
            yield fm.SceneEntity(
                timestamp=ts,
                frame_id=WORLD_FRAME,
                id=f"source/{i}",
                cylinders=[
                    fm.CylinderPrimitive(
                        pose=pose(src.x_m, src.y_m, h / 2),
                        size=fm.Vector3(x=0.8, y=0.8, z=h),
                        bottom_scale=1.0,
                        top_scale=1.0,
                        color=colour(0x444444),
                    )
                ],
                spheres=[
                    fm.SpherePrimitive(
                        pose=pose(src.x_m, src.y_m, src.release_height_m),
                        size=fm.Vector3(x=2.0, y=2.0, z=2.0),
                        color=colour(0xFF0000),
                    )
                ],
            )


_HANDLERS: dict[type, Any] = {
    SimTick: FoxgloveScene._on_tick,
    VehicleState: FoxgloveScene._on_state,
    ConcentrationReading: FoxgloveScene._on_reading,
    PlumeMesh: FoxgloveScene._on_mesh,
    PlumeState: FoxgloveScene._on_plume_state,
}
