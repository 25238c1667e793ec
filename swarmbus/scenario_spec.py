"""The scenario's schema: its sections as typed, immutable config objects (msgspec structs,
validated on conversion) and the bundled scenarios' directory. :mod:`swarmbus.scenario` reads
and checks a file into them and re-exports every name here.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Literal, NamedTuple

import msgspec

from plume_atmosphere.gases import ppm_per_g_m3
from swarmbus.messages import MissionItem
from swarmbus.session import NetworkConfig

SCENARIOS_DIR = Path(__file__).resolve().with_name("scenarios")
DEFAULT_SCENARIO = SCENARIOS_DIR / "novak2018.toml"
#: The gas-source-localisation benchmark's environments, one scenario file each.
GSL_ENVIRONMENTS_DIR = SCENARIOS_DIR / "gsl"
MAVLINK_MAX_SYSID = 254  # MAVLink systems are 1–254 (0 is broadcast, 255 ground stations)
MAX_VEHICLES = 1024  # per scenario; past MAVLINK_MAX_SYSID vehicles are on the bus only

Pos = Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
NonNeg = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Fin = Annotated[float, msgspec.Meta(ge=-1e7, le=1e7)]
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]
Degrees = Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]


class _Section(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    pass


class Origin(_Section, frozen=True, kw_only=True):
    """Geodetic origin of the ENU world frame (default: PX4 SITL's Zurich home)."""

    lat_deg: Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)] = 47.397742
    lon_deg: Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)] = 8.545594
    alt_m: Annotated[float, msgspec.Meta(ge=-500.0, le=9000.0)] = 488.0


class WorldSpec(_Section, frozen=True, kw_only=True):
    name: Name = "default"
    seed: Annotated[int, msgspec.Meta(ge=0, le=2**63 - 1)] = 0
    origin: Origin = Origin()
    # the air: what a g/m³ concentration is in ppm (ideal gas)
    temperature_k: Annotated[float, msgspec.Meta(ge=150.0, le=400.0)] = 298.15
    pressure_pa: Annotated[float, msgspec.Meta(ge=1000.0, le=200_000.0)] = 101_325.0


class Time(_Section, frozen=True, kw_only=True):
    physics_hz: Annotated[int, msgspec.Meta(ge=1, le=10_000)] = 240
    control_hz: Annotated[int, msgspec.Meta(ge=1, le=10_000)] = 120
    mode: Literal["lockstep", "realtime", "stepped"] = "lockstep"
    speed_factor: Annotated[float, msgspec.Meta(gt=0.0, le=1000.0)] = 1.0
    participant_timeout_s: Pos = 2.0
    startup_timeout_s: Pos = 60.0
    duration_s: NonNeg = 0.0  # 0: run until stopped
    checkpoint_period_s: NonNeg = 1.0  # physics checkpoints the world every S sim s; 0: never
    # lockstep: wall seconds the clock holds for an autopilot the launcher is restarting
    restart_grace_s: NonNeg = 30.0
    # lockstep: wall seconds in all a tick waits for a participant whose token is up but which
    # has not answered (slow on a loaded machine, stalled, or cut off by a partition) before it
    # is dropped, so that lateness changes no bit; 0: dropped at participant_timeout_s
    unreachable_grace_s: NonNeg = 30.0


class WindMeander(_Section, frozen=True, kw_only=True):
    """Coloured noise on the wind: Farrell et al.'s (2002) 2nd-order process (``preset`` fills
    its three numbers), or an Ornstein–Uhlenbeck process of std ``std_m_s`` and Lagrangian
    timescale ``timescale_s`` (``process = "ou"``; what ``[plume.calibration]`` derives)."""

    preset: Literal["small", "large"] | None = None
    process: Literal["farrell", "ou"] = "farrell"
    gain: NonNeg = 3.0  # Farrell's G (see docs/plume.md for its SDE form)
    damping: Pos = 0.071  # ζ
    bandwidth_rad_s: Pos = 0.71  # ω
    std_m_s: NonNeg = 0.5  # ou: stationary std of each horizontal component
    timescale_s: Annotated[float, msgspec.Meta(ge=1e-3, le=1e6)] = 10.0  # ou: T_L
    step_s: Annotated[float, msgspec.Meta(ge=1e-3, le=10.0)] = 0.05  # internal step, sim s

    def resolved(self) -> WindMeander:
        presets = {"small": (3.0, 0.071, 0.71), "large": (20.0, 0.1, 0.2)}
        if self.preset is None:
            return self
        gain, damping, bandwidth = presets[self.preset]
        return msgspec.structs.replace(
            self, preset=None, gain=gain, damping=damping, bandwidth_rad_s=bandwidth
        )


class WindField(_Section, frozen=True, kw_only=True):
    """A 2-D grid wind: the meander noise at the grid's corners, carried inwards by the mean
    wind and diffused (Farrell et al. 2002)."""

    spacing_m: Annotated[float, msgspec.Meta(ge=0.1, le=1e4)] = 10.0
    extent_m: Annotated[float, msgspec.Meta(ge=1.0, le=1e5)] = 200.0  # half-width, around 0
    diffusivity_m2_s: NonNeg = 2.0


class Wind(_Section, frozen=True, kw_only=True):
    """One wind, three consumers: the plume's advection, the vehicles' air velocity (drag) and
    their anemometers (``plume_atmosphere.wind``). ``speed_m_s``/``from_deg`` give the mean wind."""

    speed_m_s: Pos = 6.0
    from_deg: Degrees = 270.0  # meteorological: the direction it blows FROM; 270 → toward +x
    model: Literal["steady", "meander", "field"] = "steady"
    meander: WindMeander = WindMeander()
    field: WindField = WindField()


PlumeModel = Literal["gaussian", "filament", "puff"]


class Source(_Section, frozen=True, kw_only=True):
    x_m: Fin = 0.0
    y_m: Fin = 0.0
    release_rate_g_s: Pos = 10.0
    release_height_m: NonNeg = 10.0
    model: PlumeModel | None = None  # this source's model; default: [plume] model


class PlumeFilament(_Section, frozen=True, kw_only=True):
    """Farrell et al. (2002) filaments; defaults are theirs (docs/plume.md)."""

    release_rate_hz: Annotated[float, msgspec.Meta(gt=0.0, le=1e5)] = 10.0
    initial_radius_m: Pos = 0.001**0.5
    growth_m2_s: NonNeg = 0.001
    centerline_diffusivity_m2_s: NonNeg = 0.02
    step_s: Annotated[float, msgspec.Meta(ge=1e-3, le=10.0)] = 0.05
    max_age_s: Pos = 120.0  # filaments older than this are dropped
    truncate_radii: Annotated[float, msgspec.Meta(ge=1.0, le=20.0)] = 4.0  # kernel cut-off, R


class PlumePuff(_Section, frozen=True, kw_only=True):
    """CALPUFF-style puffs; σ from the plume's dispersion curves at each puff's travel."""

    release_period_s: Annotated[float, msgspec.Meta(ge=1e-3, le=600.0)] = 0.5
    step_s: Annotated[float, msgspec.Meta(ge=1e-3, le=10.0)] = 0.1  # advection step
    max_age_s: Pos = 600.0


class PlumeCalibration(_Section, frozen=True, kw_only=True):
    """Calibrate a filament or puff plume to the atmosphere (``plume_atmosphere.calibration``): the
    wind's meander (an Ornstein–Uhlenbeck process) and the filaments' relative dispersion are
    derived from ``stability``/``coefficients``, the wind speed and the release height so that
    the time-averaged field has the steady Gaussian plume's σy and σz; ``meander_share`` of
    the crosswind variance (at 30, 50, 80 m) is the centreline's meander."""

    meander_share: Annotated[float, msgspec.Meta(ge=0.0, le=0.85)] = 0.5
    roughness_m: Annotated[float, msgspec.Meta(ge=1e-4, le=2.0)] = 0.1  # z0, sets T_L


class Plume(_Section, frozen=True, kw_only=True):
    """``preset`` fills model, stability, coefficients and sources; explicit fields override."""

    preset: Literal["novak2018"] | None = None
    model: PlumeModel = "gaussian"
    filament: PlumeFilament = PlumeFilament()
    puff: PlumePuff = PlumePuff()
    state_period_s: Annotated[float, msgspec.Meta(ge=0.0, le=3600.0)] = 0.5  # plume/state; 0 off
    stability: Literal["A", "B", "C", "D", "E", "F"] = "D"
    coefficients: Literal["mcmullen", "briggs-rural", "briggs-urban", "novak2018"] = "mcmullen"
    mixing_height_m: Pos | None = None
    sources: list[Source] = msgspec.field(default_factory=lambda: [Source()])
    calibration: PlumeCalibration | None = None  # present: calibrated to the atmosphere


class Mox(_Section, frozen=True, kw_only=True):
    """A metal-oxide transducer: RS/R0 = coefficient · ppm^exponent, capped at the clean-air
    ratio; defaults: GADEN's Figaro TGS2620 curve for ethanol (R0 3 kΩ, clean air 21).
    ``rs_noise_rel``: std of the measured resistance per sample, relative to it;
    ``r0_drift_rel_per_h``: std of each sensor's baseline (R0) drift rate, relative per hour."""

    rs_r0_coefficient: Annotated[float, msgspec.Meta(gt=0.0, le=1e6)] = 62.32
    rs_r0_exponent: Annotated[float, msgspec.Meta(ge=-10.0, le=-0.001)] = -0.7155
    clean_air_rs_r0: Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] = 21.0
    r0_ohm: Annotated[float, msgspec.Meta(gt=0.0, le=1e7)] = 3000.0
    rs_noise_rel: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.0
    r0_drift_rel_per_h: Annotated[float, msgspec.Meta(ge=0.0, le=1.0)] = 0.0


class SensorPreset(NamedTuple):
    """What a sensor preset fills: time constants, gas, transducer, and the datasheet's
    detection limit and noise (ppm of ``gas`` at 298.15 K and 1 atm, turned into g/m³)."""

    rise_s: float
    decay_s: float
    gas: str
    mox: Mox | None
    detection_limit_g_m3: float = 0.0
    noise_std_g_m3: float = 0.0


def _ppm_to_g_m3(ppm: float, gas: str) -> float:
    """ppm of ``gas`` at 298.15 K and 1 atm in g/m³."""
    return ppm / ppm_per_g_m3(gas, 298.15, 101_325.0)


SENSOR_PRESETS: dict[str, SensorPreset] = {
    # GADEN's TGS2620 (rise 2.96 s, decay 15.71 s; its ethanol curve); its floor is the
    # clean-air ratio of the curve (agents.sensor), no added noise
    "mox-tgs2620": SensorPreset(2.96, 15.71, "ethanol", Mox()),
    # ION Science MiniPID 2, 0-4000 ppm range (datasheet: T90 < 3 s → τ = 3 s / ln 10,
    # minimum detection level 0.1 ppm isobutylene, taken as 3 × the noise std)
    "pid": SensorPreset(
        1.30,
        1.30,
        "isobutylene",
        None,
        _ppm_to_g_m3(0.1, "isobutylene"),
        _ppm_to_g_m3(0.1 / 3.0, "isobutylene"),
    ),
    # a fast PID for plume-structure work (Aurora Scientific 200B miniPID class: 10-90 % rise
    # well under 1 ms → τ 0.3 ms, far below any sensor period: it follows the field sample by
    # sample); detection limit and noise as the MiniPID above
    "pid-fast": SensorPreset(
        0.0003,
        0.0003,
        "isobutylene",
        None,
        _ppm_to_g_m3(0.1, "isobutylene"),
        _ppm_to_g_m3(0.1 / 3.0, "isobutylene"),
    ),
}


class Sensor(_Section, frozen=True, kw_only=True):
    """Concentration sensor model. ``preset = "novak2018"`` is the seed's [0.01, 0.2] window;
    ``mox-tgs2620``, ``pid`` and ``pid-fast`` fill the fields left unset (rise, decay, gas,
    mox) and those left at 0 (detection limit, noise std)."""

    preset: Literal["novak2018", "ideal", "mox-tgs2620", "pid", "pid-fast"] | None = None
    detection_limit_g_m3: NonNeg = 0.0  # below → 0
    saturation_g_m3: Pos | None = None  # above → saturation
    noise_std_g_m3: NonNeg = 0.0
    time_constant_s: NonNeg = 0.0  # first-order response lag; 0: none
    period_ticks: Annotated[int, msgspec.Meta(ge=1, le=100_000)] = 1
    # lag while the true value is above (rise) / below (decay) the state; unset: time_constant_s
    rise_time_constant_s: NonNeg | None = None
    decay_time_constant_s: NonNeg | None = None
    resolution_g_m3: NonNeg = 0.0  # quantisation step of the output; 0: none
    noise_rel: Annotated[float, msgspec.Meta(ge=0.0, le=10.0)] = 0.0  # std / lagged value
    gas: Name | None = None  # also report ppm of this gas (plume_atmosphere.gases)
    mox: Mox | None = None  # a metal-oxide transducer: the lag acts on its RS/R0 (with gas)

    def resolved(self) -> Sensor:
        if self.preset == "novak2018":
            return msgspec.structs.replace(
                self, preset=None, detection_limit_g_m3=0.01, saturation_g_m3=0.2
            )
        if self.preset == "ideal":
            return msgspec.structs.replace(
                self, preset=None, detection_limit_g_m3=0.0, saturation_g_m3=None
            )
        if self.preset is not None:
            p = SENSOR_PRESETS[self.preset]
            return msgspec.structs.replace(
                self,
                preset=None,
                rise_time_constant_s=_or(self.rise_time_constant_s, p.rise_s),
                decay_time_constant_s=_or(self.decay_time_constant_s, p.decay_s),
                gas=self.gas or p.gas,
                mox=self.mox or p.mox,
                detection_limit_g_m3=self.detection_limit_g_m3 or p.detection_limit_g_m3,
                noise_std_g_m3=self.noise_std_g_m3 or p.noise_std_g_m3,
            )
        return self

    @property
    def rise_s(self) -> float:
        return _or(self.rise_time_constant_s, self.time_constant_s)

    @property
    def decay_s(self) -> float:
        return _or(self.decay_time_constant_s, self.time_constant_s)


def _or(value: float | None, default: float) -> float:
    return default if value is None else value


class AnemometerSpec(_Section, frozen=True, kw_only=True):
    """Every vehicle's anemometer (agents.anemometer): the scenario's wind plus noise."""

    period_ticks: Annotated[int, msgspec.Meta(ge=0, le=100_000)] = 0  # 0: no anemometer
    noise_std_m_s: NonNeg = 0.1  # per axis (GADEN's anemometer noise)


class Failsafe(_Section, frozen=True, kw_only=True):
    datalink_loss_action: Literal["none", "hold", "land", "rtl"] = "rtl"
    datalink_timeout_s: Pos = 10.0
    datalink_required: bool = False  # only armed once a GCS heartbeat was seen
    offboard_loss_action: Literal["hold", "land", "rtl"] = "hold"
    offboard_timeout_s: Pos = 0.5
    geofence_max_alt_m: NonNeg = 120.0  # above home; 0: off (PX4's GF_MAX_VER_DIST)
    geofence_max_distance_m: NonNeg = 0.0  # from home; 0: off, PX4's GF_MAX_HOR_DIST default
    rtl_altitude_m: Pos = 15.0
    takeoff_altitude_m: Pos = 2.5
    crash_speed_m_s: Pos = 3.0
    # Realtime mode, a link to the physics lost (docs/reliability.md, "Partitions"): the
    # autopilot lands after this long without a tick (never less than time.participant_timeout_s);
    # the physics lands a vehicle without commands at this speed (PX4's MPC_LAND_SPEED).
    state_loss_timeout_s: Pos = 3.0
    descend_speed_m_s: Pos = 0.7


class VehicleSpec(_Section, frozen=True, kw_only=True):
    id: Name
    type: Name = "iris"
    # MAVLink system id for the gateway; default: index + 1 for the first 254 vehicles, none after
    sysid: Annotated[int, msgspec.Meta(ge=1, le=MAVLINK_MAX_SYSID)] | None = None
    spawn_enu_m: tuple[Fin, Fin, Fin] = (0.0, 0.0, 0.0)
    spawn_yaw_deg: Degrees = 0.0
    mission: list[MissionItem] = []
    behavior: str | None = None  # "module:Class" plug-in for offboard mode
    failsafe: Failsafe | None = None  # overrides the scenario's [failsafe]


class GatewaySpec(_Section, frozen=True, kw_only=True):
    host: str = "127.0.0.1"  # where the ground station listens (the GCS link's peer)
    # where the API clients (MAVSDK, offboard programs) listen; empty: `host`
    api_host: Annotated[str, msgspec.Meta(max_length=253)] = ""
    gcs_port: Annotated[int, msgspec.Meta(ge=1, le=65535)] = 14550
    api_port_base: Annotated[int, msgspec.Meta(ge=1, le=65535)] = 14540
    signing_key_hex: Annotated[str, msgspec.Meta(pattern=r"^[0-9a-fA-F]{64}$")] | None = None
    signing_key_file: Annotated[str, msgspec.Meta(min_length=1, max_length=4096)] | None = None
    telemetry_hz: Annotated[float, msgspec.Meta(gt=0.0, le=100.0)] = 4.0
    # refuse a force disarm sent to every system (target_system 0), which is always logged
    refuse_broadcast_disarm: bool = False


class Env(_Section, frozen=True, kw_only=True):
    """The Gymnasium / PettingZoo environments: where an episode starts and when it ends.

    ``reset(seed=…)`` draws each vehicle's ground position (x, y) and take-off altitude z
    uniformly from the box ``start_min_enu_m``..``start_max_enu_m``."""

    start_min_enu_m: tuple[Fin, Fin, Fin] = (30.0, -15.0, 8.0)
    start_max_enu_m: tuple[Fin, Fin, Fin] = (60.0, 15.0, 12.0)
    success_radius_m: Pos = 3.0
    time_limit_s: Pos = 60.0


class Scenario(_Section, frozen=True, kw_only=True):
    world: WorldSpec = WorldSpec()
    time: Time = Time()
    network: NetworkConfig = NetworkConfig()
    wind: Wind = Wind()
    plume: Plume = Plume()
    sensor: Sensor = Sensor()
    anemometer: AnemometerSpec = AnemometerSpec()
    failsafe: Failsafe = Failsafe()
    gateway: GatewaySpec = GatewaySpec()
    env: Env = Env()
    vehicles: Annotated[list[VehicleSpec], msgspec.Meta(min_length=1, max_length=MAX_VEHICLES)]

    def vehicle(self, vehicle_id: str) -> VehicleSpec:
        for v in self.vehicles:
            if v.id == vehicle_id:
                return v
        raise KeyError(vehicle_id)

    def failsafe_for(self, vehicle_id: str) -> Failsafe:
        return self.vehicle(vehicle_id).failsafe or self.failsafe

    def sysid_of(self, vehicle_id: str) -> int | None:
        """The vehicle's MAVLink system id: its ``sysid``, else its index + 1 for the first 254
        vehicles; None for the others (MAVLink addresses systems 1–254: not on MAVLink)."""
        for index, v in enumerate(self.vehicles):
            if v.id == vehicle_id:
                return sysid_at(index, v)
        raise KeyError(vehicle_id)

    def not_on_mavlink(self, vehicle_ids: Iterable[str] | None = None) -> list[str]:
        """Those of ``vehicle_ids`` (default: all) that have no MAVLink sysid."""
        wanted = None if vehicle_ids is None else set(vehicle_ids)
        return [
            v.id
            for i, v in enumerate(self.vehicles)
            if sysid_at(i, v) is None and (wanted is None or v.id in wanted)
        ]

    @property
    def substeps(self) -> int:
        return self.time.physics_hz // self.time.control_hz


def sysid_at(index: int, v: VehicleSpec) -> int | None:
    """The MAVLink system id of ``v``, the vehicle at ``index`` (see :meth:`Scenario.sysid_of`)."""
    if v.sysid is not None:
        return v.sysid
    return index + 1 if index < MAVLINK_MAX_SYSID else None


def not_on_mavlink_note(count: int) -> str:
    """The one line the gateway and ``plumeswarm up`` print when vehicles have no sysid."""
    return (
        f"{count} vehicle(s) not on MAVLink: MAVLink addresses systems 1–{MAVLINK_MAX_SYSID}, "
        f"so only vehicles with a sysid (explicit, or the first {MAVLINK_MAX_SYSID} in scenario "
        "order) are served by the gateway; the others fly on the bus as usual"
    )
