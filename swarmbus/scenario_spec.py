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
from swarmbus.radio import RadioSpec
from swarmbus.session import NetworkConfig

SCENARIOS_DIR = Path(__file__).resolve().with_name("scenarios")
DEFAULT_SCENARIO = SCENARIOS_DIR / "novak2018.toml"
#: The gas-source-localisation benchmark's environments, one scenario file each.
GSL_ENVIRONMENTS_DIR = SCENARIOS_DIR / "gsl"
GSL_TUNING_DIR = GSL_ENVIRONMENTS_DIR / "tuning"  # environments tuning uses, never published
FAMILY_TABLE = "randomise"  # a randomised environment family's ranges, not the scenario's
MAVLINK_MAX_SYSID = 254  # MAVLink systems are 1–254 (0 is broadcast, 255 ground stations)
MAX_VEHICLES = 1024  # per scenario; past MAVLINK_MAX_SYSID vehicles are on the bus only

Pos = Annotated[float, msgspec.Meta(gt=0.0, le=1e9)]
NonNeg = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Fin = Annotated[float, msgspec.Meta(ge=-1e7, le=1e7)]
Name = Annotated[str, msgspec.Meta(pattern=r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,63}$")]
Degrees = Annotated[float, msgspec.Meta(ge=-360.0, le=360.0)]

#: Keys renamed in this release, by the name of the table that holds them: old key → new key.
#: A file or a ``--set`` with an old key still loads, to the same value, and one line is
#: logged naming the old key and the new one; the old names go in the next release.
RENAMED_KEYS: dict[str, dict[str, str]] = {
    "failsafe": {"geofence_max_alt_m": "geofence_max_altitude_m"},
}


def _doc(description: str) -> msgspec.Meta:
    """A field's description: what ``plumeswarm scenario schema`` says of it."""
    return msgspec.Meta(description=description)


class _Section(msgspec.Struct, frozen=True, forbid_unknown_fields=True):
    pass


class Origin(_Section, frozen=True, kw_only=True):
    """Geodetic origin of the ENU world frame (default: PX4 SITL's Zurich home)."""

    lat_deg: Annotated[
        float,
        msgspec.Meta(
            ge=-90.0, le=90.0, description="Latitude of the world frame's origin, degrees."
        ),
    ] = 47.397742
    lon_deg: Annotated[
        float,
        msgspec.Meta(
            ge=-180.0, le=180.0, description="Longitude of the world frame's origin, degrees."
        ),
    ] = 8.545594
    alt_m: Annotated[
        float,
        msgspec.Meta(
            ge=-500.0, le=9000.0, description="Altitude of the origin above mean sea level, m."
        ),
    ] = 488.0


class WorldSpec(_Section, frozen=True, kw_only=True):
    """The world: its name on the bus, the seed of its random processes, its origin and air."""

    name: Annotated[
        Name,
        _doc(
            "The world's name: every bus key of the run is under it (two worlds on one bus do "
            "not mix)."
        ),
    ] = "default"
    seed: Annotated[
        int,
        msgspec.Meta(
            ge=0,
            le=2**63 - 1,
            description=(
                "Seed of every random process of the run (plume, wind, sensors): same seed, same "
                "bits."
            ),
        ),
    ] = 0
    origin: Annotated[Origin, _doc("Geodetic origin of the ENU world frame.")] = Origin()
    temperature_k: Annotated[
        float,
        msgspec.Meta(
            ge=150.0,
            le=400.0,
            description="Air temperature, K: converts a g/m³ concentration to ppm (ideal gas).",
        ),
    ] = 298.15
    pressure_pa: Annotated[
        float,
        msgspec.Meta(
            ge=1000.0,
            le=200_000.0,
            description="Air pressure, Pa: converts a g/m³ concentration to ppm (ideal gas).",
        ),
    ] = 101_325.0


class Time(_Section, frozen=True, kw_only=True):
    """The clock: physics and control rates, how time advances, and the run's timeouts."""

    physics_hz: Annotated[
        int, msgspec.Meta(ge=1, le=10_000, description="Physics steps per simulated second.")
    ] = 240
    control_hz: Annotated[
        int,
        msgspec.Meta(
            ge=1,
            le=10_000,
            description=(
                "Control ticks per simulated second (autopilots, sensors); divides physics_hz."
            ),
        ),
    ] = 120
    mode: Annotated[
        Literal["lockstep", "realtime", "stepped"],
        _doc(
            "Clock: lockstep (as fast as the slowest participant), realtime (paced to the wall"
            " clock) or stepped (a client steps it)."
        ),
    ] = "lockstep"
    speed_factor: Annotated[
        float,
        msgspec.Meta(
            gt=0.0, le=1000.0, description="Realtime mode: simulated seconds per wall second."
        ),
    ] = 1.0
    participant_timeout_s: Annotated[
        Pos, _doc("Wall seconds without an answer after which a participant counts as gone.")
    ] = 2.0
    startup_timeout_s: Annotated[
        Pos, _doc("Wall seconds the processes of a run may take to start and join.")
    ] = 60.0
    duration_s: Annotated[NonNeg, _doc("Simulated seconds the run lasts; 0: until stopped.")] = 0.0
    checkpoint_period_s: Annotated[
        NonNeg,
        _doc(
            "Simulated seconds between the physics' checkpoints of the world (restart after a "
            "crash); 0: never."
        ),
    ] = 1.0
    restart_grace_s: Annotated[
        NonNeg,
        _doc("Lockstep: wall seconds the clock holds for an autopilot the launcher is restarting."),
    ] = 30.0
    # lockstep: wall seconds in all a tick waits for a participant whose token is up but which
    # has not answered (slow on a loaded machine, stalled, or cut off by a partition) before it
    # is dropped, so that lateness changes no bit; 0: dropped at participant_timeout_s
    unreachable_grace_s: Annotated[
        NonNeg,
        _doc(
            "Lockstep: wall seconds a tick waits in all for a participant whose token is up "
            "but which has not answered, before it is dropped; 0: dropped at "
            "participant_timeout_s."
        ),
    ] = 30.0


class WindMeander(_Section, frozen=True, kw_only=True):
    """Coloured noise on the wind: Farrell et al.'s (2002) 2nd-order process (``preset`` fills
    its three numbers), or an Ornstein–Uhlenbeck process of std ``std_m_s`` and Lagrangian
    timescale ``timescale_s`` (``process = "ou"``; what ``[plume.calibration]`` derives)."""

    preset: Annotated[
        Literal["small", "large"] | None,
        _doc(
            "Fills gain, damping and bandwidth_rad_s with Farrell et al.'s small or large meander."
        ),
    ] = None
    process: Annotated[
        Literal["farrell", "ou"],
        _doc(
            "farrell: Farrell et al.'s 2nd-order coloured noise; ou: an Ornstein-Uhlenbeck "
            "process (std_m_s, timescale_s)."
        ),
    ] = "farrell"
    gain: Annotated[NonNeg, _doc("Farrell's G, the noise gain (docs/plume.md gives the SDE).")] = (
        3.0
    )
    damping: Annotated[Pos, _doc("Farrell's damping ratio ζ.")] = 0.071
    bandwidth_rad_s: Annotated[Pos, _doc("Farrell's bandwidth ω, rad/s.")] = 0.71
    std_m_s: Annotated[
        NonNeg, _doc("ou: stationary standard deviation of each horizontal wind component, m/s.")
    ] = 0.5
    timescale_s: Annotated[
        float, msgspec.Meta(ge=1e-3, le=1e6, description="ou: Lagrangian timescale T_L, s.")
    ] = 10.0
    step_s: Annotated[
        float, msgspec.Meta(ge=1e-3, le=10.0, description="Internal integration step, simulated s.")
    ] = 0.05

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

    spacing_m: Annotated[float, msgspec.Meta(ge=0.1, le=1e4, description="Grid spacing, m.")] = 10.0
    extent_m: Annotated[
        float,
        msgspec.Meta(
            ge=1.0, le=1e5, description="Half-width of the square grid around the origin, m."
        ),
    ] = 200.0
    diffusivity_m2_s: Annotated[
        NonNeg, _doc("Diffusivity that spreads the corners' noise inwards, m²/s.")
    ] = 2.0


class WindTurbulence(_Section, frozen=True, kw_only=True):
    """Local turbulence on top of the wind: a seeded, spatially correlated perturbation frozen in
    the frame of the mean wind (``plume_atmosphere.wind.TurbulenceField``). Its intensities,
    length scale and timescale are derived from the atmosphere when the file is read
    (``plume_atmosphere.calibration.derive_turbulence``: ``share`` of the stability class's
    crosswind and vertical variance); explicit values of those three are replaced."""

    share: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=0.85,
            description=(
                "Share of the stability class's crosswind and vertical variance the local "
                "turbulence carries."
            ),
        ),
    ] = 0.3
    modes: Annotated[
        int,
        msgspec.Meta(
            ge=1, le=1024, description="Random Fourier modes per component (more: finer, slower)."
        ),
    ] = 32
    std_m_s: Annotated[
        tuple[NonNeg, NonNeg, NonNeg],
        _doc("Derived: standard deviation along the mean wind, across it and vertically, m/s."),
    ] = (0.0, 0.0, 0.0)
    length_scale_m: Annotated[
        float,
        msgspec.Meta(ge=1e-3, le=1e6, description="Derived: integral length scale L, m."),
    ] = 1.0
    timescale_s: Annotated[
        float,
        msgspec.Meta(ge=1e-3, le=1e6, description="Derived: decorrelation timescale T, s."),
    ] = 1.0


class Wind(_Section, frozen=True, kw_only=True):
    """One wind, three consumers: the plume's advection, the vehicles' air velocity (drag) and
    their anemometers (``plume_atmosphere.wind``). ``speed_m_s``/``from_deg`` give the mean wind."""

    speed_m_s: Annotated[Pos, _doc("Mean wind speed, m/s.")] = 6.0
    from_deg: Annotated[
        Degrees,
        _doc(
            "Direction the wind blows from, meteorological degrees (270: from the west, toward +x)."
        ),
    ] = 270.0
    model: Annotated[
        Literal["steady", "meander", "field"],
        _doc(
            "steady: the mean wind only; meander: plus coloured noise ([wind.meander]); field:"
            " a 2-D grid ([wind.field])."
        ),
    ] = "steady"
    meander: Annotated[WindMeander, _doc("The meander's noise process.")] = WindMeander()
    field: Annotated[WindField, _doc("The gridded wind's grid.")] = WindField()
    turbulence: Annotated[
        WindTurbulence | None,
        _doc("Present: local turbulence on top of the wind (docs/plume.md); absent: none."),
    ] = None


PlumeModel = Literal["gaussian", "filament", "puff"]


class Source(_Section, frozen=True, kw_only=True):
    """One gas source: where it is, how much it releases, and from how high."""

    x_m: Annotated[Fin, _doc("East position of the source in the world frame, m.")] = 0.0
    y_m: Annotated[Fin, _doc("North position of the source in the world frame, m.")] = 0.0
    release_rate_g_s: Annotated[Pos, _doc("Mass released per second, g/s.")] = 10.0
    release_height_m: Annotated[NonNeg, _doc("Height of the release above the ground, m.")] = 10.0
    model: Annotated[
        PlumeModel | None, _doc("This source's plume model; unset: the [plume] model.")
    ] = None


class PlumeFilament(_Section, frozen=True, kw_only=True):
    """Farrell et al. (2002) filaments; defaults are theirs (docs/plume.md)."""

    release_rate_hz: Annotated[
        float, msgspec.Meta(gt=0.0, le=1e5, description="Filaments released per second.")
    ] = 10.0
    initial_radius_m: Annotated[Pos, _doc("Radius of a new filament, m.")] = 0.001**0.5
    growth_m2_s: Annotated[NonNeg, _doc("Growth of a filament's squared radius, m²/s.")] = 0.001
    centerline_diffusivity_m2_s: Annotated[
        NonNeg, _doc("Relative diffusivity of the filaments' centres, m²/s.")
    ] = 0.02
    step_s: Annotated[
        float, msgspec.Meta(ge=1e-3, le=10.0, description="Integration step, simulated s.")
    ] = 0.05
    max_age_s: Annotated[Pos, _doc("Filaments older than this are dropped, simulated s.")] = 120.0
    truncate_radii: Annotated[
        float,
        msgspec.Meta(ge=1.0, le=20.0, description="Cut-off of a filament's kernel, in radii."),
    ] = 4.0


class PlumePuff(_Section, frozen=True, kw_only=True):
    """CALPUFF-style puffs; σ from the plume's dispersion curves at each puff's travel."""

    release_period_s: Annotated[
        float, msgspec.Meta(ge=1e-3, le=600.0, description="Simulated seconds between two puffs.")
    ] = 0.5
    step_s: Annotated[
        float, msgspec.Meta(ge=1e-3, le=10.0, description="Advection step, simulated s.")
    ] = 0.1
    max_age_s: Annotated[Pos, _doc("Puffs older than this are dropped, simulated s.")] = 600.0


class PlumeCalibration(_Section, frozen=True, kw_only=True):
    """Calibrate a filament or puff plume to the atmosphere (``plume_atmosphere.calibration``): the
    wind's meander (an Ornstein–Uhlenbeck process) and the filaments' relative dispersion are
    derived from ``stability``/``coefficients``, the wind speed and the release height so that
    the time-averaged field has the steady Gaussian plume's σy and σz; ``meander_share`` of
    the crosswind variance (at 30, 50, 80 m) is the centreline's meander."""

    meander_share: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=0.85,
            description=(
                "Share of the crosswind variance that is the centreline's meander (the rest is the"
                " filaments' own spread)."
            ),
        ),
    ] = 0.5
    roughness_m: Annotated[
        float,
        msgspec.Meta(
            ge=1e-4,
            le=2.0,
            description="Surface roughness length z0, m: sets the Lagrangian timescale.",
        ),
    ] = 0.1


class Plume(_Section, frozen=True, kw_only=True):
    """``preset`` fills model, stability, coefficients and sources; explicit fields override."""

    preset: Annotated[
        Literal["novak2018"] | None,
        _doc(
            "Fills model, stability, coefficients and sources (novak2018: the seed's plume); "
            "explicit fields override."
        ),
    ] = None
    model: Annotated[
        PlumeModel,
        _doc(
            "gaussian: the steady Gaussian plume; filament: Farrell et al.'s filaments; puff: "
            "CALPUFF-style puffs."
        ),
    ] = "gaussian"
    filament: Annotated[PlumeFilament, _doc("The filament model's parameters.")] = PlumeFilament()
    puff: Annotated[PlumePuff, _doc("The puff model's parameters.")] = PlumePuff()
    state_period_s: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=3600.0,
            description=(
                "Simulated seconds between two plume/state messages of a filament or puff plume; "
                "0: never."
            ),
        ),
    ] = 0.5
    stability: Annotated[
        Literal["A", "B", "C", "D", "E", "F"],
        _doc("Pasquill-Gifford stability class, A (very unstable) to F (stable)."),
    ] = "D"
    coefficients: Annotated[
        Literal["mcmullen", "briggs-rural", "briggs-urban", "novak2018"],
        _doc("Dispersion curves σy(x), σz(x) of the stability class."),
    ] = "mcmullen"
    mixing_height_m: Annotated[
        Pos | None,
        _doc("Height of the mixing layer's lid, m, which reflects the plume; unset: no lid."),
    ] = None
    sources: Annotated[list[Source], _doc("The sources, one table each.")] = msgspec.field(
        default_factory=lambda: [Source()]
    )
    calibration: Annotated[
        PlumeCalibration | None,
        _doc(
            "Present: the wind's meander and the filaments are derived to match the Gaussian "
            "plume's σy and σz."
        ),
    ] = None


class Mox(_Section, frozen=True, kw_only=True):
    """A metal-oxide transducer: RS/R0 = coefficient · ppm^exponent, capped at the clean-air
    ratio; defaults: GADEN's Figaro TGS2620 curve for ethanol (R0 3 kΩ, clean air 21).
    ``rs_noise_rel``: std of the measured resistance per sample, relative to it;
    ``r0_drift_rel_per_h``: std of each sensor's baseline (R0) drift rate, relative per hour."""

    rs_r0_coefficient: Annotated[
        float,
        msgspec.Meta(
            gt=0.0,
            le=1e6,
            description="The curve's coefficient: RS/R0 = coefficient · ppm^exponent.",
        ),
    ] = 62.32
    rs_r0_exponent: Annotated[
        float, msgspec.Meta(ge=-10.0, le=-0.001, description="The curve's exponent (negative).")
    ] = -0.7155
    clean_air_rs_r0: Annotated[
        float, msgspec.Meta(gt=0.0, le=100.0, description="RS/R0 in clean air: the curve's cap.")
    ] = 21.0
    r0_ohm: Annotated[
        float, msgspec.Meta(gt=0.0, le=1e7, description="The sensor's resistance R0, Ω.")
    ] = 3000.0
    rs_noise_rel: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=1.0,
            description="Standard deviation of the measured resistance per sample, relative to it.",
        ),
    ] = 0.0
    r0_drift_rel_per_h: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=1.0,
            description=(
                "Standard deviation of each sensor's baseline (R0) drift rate, relative per hour."
            ),
        ),
    ] = 0.0


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

    preset: Annotated[
        Literal["novak2018", "ideal", "mox-tgs2620", "pid", "pid-fast"] | None,
        _doc(
            "Fills the fields left unset: novak2018 (the seed's [0.01, 0.2] g/m³ window), "
            "ideal, mox-tgs2620, pid, pid-fast."
        ),
    ] = None
    detection_limit_g_m3: Annotated[NonNeg, _doc("Readings below are 0, g/m³.")] = 0.0
    saturation_g_m3: Annotated[
        Pos | None, _doc("Readings above are this, g/m³; unset: no saturation.")
    ] = None
    noise_std_g_m3: Annotated[NonNeg, _doc("Standard deviation of the additive noise, g/m³.")] = 0.0
    time_constant_s: Annotated[NonNeg, _doc("First-order response lag, s; 0: none.")] = 0.0
    period_ticks: Annotated[
        int, msgspec.Meta(ge=1, le=100_000, description="A reading every N control ticks.")
    ] = 1
    rise_time_constant_s: Annotated[
        NonNeg | None,
        _doc("Lag while the true value is above the state, s; unset: time_constant_s."),
    ] = None
    decay_time_constant_s: Annotated[
        NonNeg | None,
        _doc("Lag while the true value is below the state, s; unset: time_constant_s."),
    ] = None
    resolution_g_m3: Annotated[NonNeg, _doc("Quantisation step of the output, g/m³; 0: none.")] = (
        0.0
    )
    noise_rel: Annotated[
        float,
        msgspec.Meta(
            ge=0.0,
            le=10.0,
            description=(
                "Standard deviation of the multiplicative noise, relative to the lagged value."
            ),
        ),
    ] = 0.0
    gas: Annotated[Name | None, _doc("Also report ppm of this gas (plume_atmosphere.gases).")] = (
        None
    )
    mox: Annotated[
        Mox | None, _doc("A metal-oxide transducer: the lag acts on its RS/R0 (needs gas).")
    ] = None

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

    period_ticks: Annotated[
        int,
        msgspec.Meta(
            ge=0, le=100_000, description="A reading every N control ticks; 0: no anemometer."
        ),
    ] = 0
    noise_std_m_s: Annotated[NonNeg, _doc("Standard deviation of the noise per axis, m/s.")] = 0.1


class Failsafe(_Section, frozen=True, kw_only=True):
    """What an autopilot does when a link is lost or a limit is crossed (PX4's failsafes)."""

    datalink_loss_action: Annotated[
        Literal["none", "hold", "land", "rtl"],
        _doc("What a vehicle does when the ground station's heartbeat is lost."),
    ] = "rtl"
    datalink_timeout_s: Annotated[
        Pos, _doc("Seconds without a ground-station heartbeat before the datalink counts as lost.")
    ] = 10.0
    datalink_required: Annotated[
        bool, _doc("Arm only once a ground-station heartbeat was seen.")
    ] = False
    offboard_loss_action: Annotated[
        Literal["hold", "land", "rtl"],
        _doc("What a vehicle in offboard mode does when its setpoints stop."),
    ] = "hold"
    offboard_timeout_s: Annotated[
        Pos, _doc("Seconds without an offboard setpoint before offboard counts as lost.")
    ] = 0.5
    geofence_max_altitude_m: Annotated[
        NonNeg, _doc("Highest altitude above home, m; 0: off (PX4's GF_MAX_VER_DIST).")
    ] = 120.0
    geofence_max_distance_m: Annotated[
        NonNeg, _doc("Farthest horizontal distance from home, m; 0: off (PX4's GF_MAX_HOR_DIST).")
    ] = 0.0
    rtl_altitude_m: Annotated[Pos, _doc("Altitude of a return to launch, above home, m.")] = 15.0
    takeoff_altitude_m: Annotated[
        Pos, _doc("Altitude of a take-off without one given, above home, m.")
    ] = 2.5
    crash_speed_m_s: Annotated[Pos, _doc("Ground contact faster than this is a crash, m/s.")] = 3.0
    # Realtime mode, a link to the physics lost (docs/reliability.md, "Partitions"): the
    # autopilot lands after this long without a tick (never less than time.participant_timeout_s).
    state_loss_timeout_s: Annotated[
        Pos,
        _doc(
            "Realtime mode: the autopilot lands after this long without a tick from the "
            "physics, s (never less than time.participant_timeout_s)."
        ),
    ] = 3.0
    hold_s: Annotated[
        NonNeg,
        _doc(
            "Any clock mode: the physics holds a vehicle without commands (its autopilot dropped, "
            "or late past the tick's deadline) this long, s, then lands it (PX4's COM_FAIL_ACT_T)."
        ),
    ] = 5.0
    descend_speed_m_s: Annotated[
        Pos,
        _doc(
            "Any clock mode: the physics lands a vehicle without commands at this speed, m/s "
            "(PX4's MPC_LAND_SPEED)."
        ),
    ] = 0.7


class VehicleSpec(_Section, frozen=True, kw_only=True):
    """One vehicle: its id, type, MAVLink system id, spawn pose, mission and behaviour."""

    id: Annotated[
        Name, _doc("The vehicle's id, unique in the scenario: its bus keys are under it.")
    ]
    type: Annotated[Name, _doc("Vehicle type: a file of swarmbus/vehicles (iris, ...).")] = "iris"
    sysid: Annotated[
        Annotated[int, msgspec.Meta(ge=1, le=MAVLINK_MAX_SYSID)] | None,
        _doc(
            "MAVLink system id for the gateway (1-254, unique); unset: index + 1 for the first"
            " 254 vehicles, none after."
        ),
    ] = None
    spawn_enu_m: Annotated[tuple[Fin, Fin, Fin], _doc("Spawn position, world ENU m.")] = (
        0.0,
        0.0,
        0.0,
    )
    spawn_yaw_deg: Annotated[Degrees, _doc("Spawn heading, degrees.")] = 0.0
    mission: Annotated[list[MissionItem], _doc("Mission items flown on mission start.")] = []
    behavior: Annotated[
        str | None, _doc("A 'module:Class' plug-in that flies the vehicle in offboard mode.")
    ] = None
    failsafe: Annotated[
        Failsafe | None, _doc("This vehicle's failsafe; unset: the scenario's [failsafe].")
    ] = None


class GatewaySpec(_Section, frozen=True, kw_only=True):
    """The MAVLink gateway: the ports of its ground-station and API links, signing, rates."""

    host: Annotated[
        str, _doc("Where the ground station listens (the GCS link's peer); its link binds to it.")
    ] = "127.0.0.1"
    api_host: Annotated[
        str,
        msgspec.Meta(
            max_length=253,
            description="Where the API clients (MAVSDK, offboard programs) listen; empty: host.",
        ),
    ] = ""
    gcs_port: Annotated[
        int,
        msgspec.Meta(
            ge=1, le=65535, description="UDP port of the ground-station link (QGroundControl)."
        ),
    ] = 14550
    api_port_base: Annotated[
        int,
        msgspec.Meta(
            ge=1,
            le=65535,
            description=(
                "UDP port of vehicle 0's API link (MAVSDK, offboard programs); vehicle i's is this"
                " + i."
            ),
        ),
    ] = 14540
    signing_key_hex: Annotated[
        Annotated[str, msgspec.Meta(pattern=r"^[0-9a-fA-F]{64}$")] | None,
        _doc("MAVLink 2 signing key, 64 hex digits; unset: no signing (or signing_key_file)."),
    ] = None
    signing_key_file: Annotated[
        Annotated[str, msgspec.Meta(min_length=1, max_length=4096)] | None,
        _doc("File holding the MAVLink 2 signing key (private to its owner; ~ expanded)."),
    ] = None
    telemetry_hz: Annotated[
        float,
        msgspec.Meta(
            gt=0.0, le=100.0, description="Rate of the fast telemetry streams per simulated second."
        ),
    ] = 4.0
    refuse_broadcast_disarm: Annotated[
        bool,
        _doc("Refuse a force disarm sent to every system (target_system 0); it is always logged."),
    ] = False


class Env(_Section, frozen=True, kw_only=True):
    """The Gymnasium / PettingZoo environments: where an episode starts and when it ends.

    ``reset(seed=…)`` draws each vehicle's ground position (x, y) and take-off altitude z
    uniformly from the box ``start_min_enu_m``..``start_max_enu_m``."""

    start_min_enu_m: Annotated[
        tuple[Fin, Fin, Fin],
        _doc(
            "Lower corner of the box an episode's start is drawn from (x, y ground position; z"
            " take-off altitude), m."
        ),
    ] = (30.0, -15.0, 8.0)
    start_max_enu_m: Annotated[tuple[Fin, Fin, Fin], _doc("Upper corner of the start box, m.")] = (
        60.0,
        15.0,
        12.0,
    )
    success_radius_m: Annotated[
        Pos, _doc("An episode succeeds within this distance of the source, m.")
    ] = 3.0
    time_limit_s: Annotated[Pos, _doc("An episode ends after this many simulated seconds.")] = 60.0


class Scenario(_Section, frozen=True, kw_only=True):
    """A plumeswarm scenario file: the world, its clock, network, wind, plume, sensors,
    failsafes, gateway, environments and vehicles."""

    world: Annotated[WorldSpec, _doc("The world: name, seed, origin, air.")] = WorldSpec()
    time: Annotated[Time, _doc("The clock: rates, mode, timeouts.")] = Time()
    network: Annotated[NetworkConfig, _doc("How the processes join the Zenoh network.")] = (
        NetworkConfig()
    )
    wind: Annotated[Wind, _doc("The wind: mean, meander or field.")] = Wind()
    plume: Annotated[Plume, _doc("The gas plume: model, sources, dispersion.")] = Plume()
    sensor: Annotated[Sensor, _doc("Every vehicle's concentration sensor.")] = Sensor()
    anemometer: Annotated[AnemometerSpec, _doc("Every vehicle's anemometer.")] = AnemometerSpec()
    failsafe: Annotated[
        Failsafe, _doc("The vehicles' failsafes (a vehicle's own [vehicles.failsafe] overrides).")
    ] = Failsafe()
    gateway: Annotated[GatewaySpec, _doc("The MAVLink gateway for ground stations and MAVSDK.")] = (
        GatewaySpec()
    )
    env: Annotated[Env, _doc("The Gymnasium / PettingZoo environments' episodes.")] = Env()
    radio: Annotated[
        RadioSpec,
        _doc("The radio between vehicles: range, loss, latency, size (default: perfect)."),
    ] = RadioSpec()
    vehicles: Annotated[
        Annotated[list[VehicleSpec], msgspec.Meta(min_length=1, max_length=MAX_VEHICLES)],
        _doc("The vehicles, one [[vehicles]] table each."),
    ]

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
