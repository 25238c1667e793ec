"""The gateway's options (``plumeswarm node gateway --set KEY=VALUE``, :class:`GatewayOptions`)
over the scenario's ``[gateway]`` section, and its MAVLink 2 signing key. See
docs/qgroundcontrol.md.
"""

from __future__ import annotations

import ipaddress
import re
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Literal, Self

import msgspec

from gcs_bridge.dialect import mavlink
from gcs_bridge.telemetry import default_rates
from swarmbus.options import OptionError, RoleOptions
from swarmbus.scenario import GatewaySpec, Scenario

Port = Annotated[int, msgspec.Meta(ge=0, le=65535)]


class GatewayOptions(RoleOptions, frozen=True, kw_only=True):
    """The gateway role's options; the scenario's ``[gateway]`` gives the links' addresses."""

    telemetry_hz: Annotated[float, msgspec.Meta(ge=0.01, le=1000.0)] = 4.0
    """Default rate of the fast telemetry streams (per sim second; default: ``[gateway]``'s)."""
    rate: dict[str, Annotated[float, msgspec.Meta(ge=0.0, le=1000.0)]] = msgspec.field(
        default_factory=dict
    )
    """One stream's rate, ``rate.<MESSAGE>=HZ`` (e.g. ``rate.ATTITUDE=10``; 0 turns it off)."""
    bind_host: str = ""
    """Address every UDP socket binds (empty: per link, below)."""
    gcs_bind_host: str = ""
    """Address the GCS link binds (empty: ``bind_host``, else 127.0.0.1 when ``[gateway] host``
    is on loopback, else 0.0.0.0)."""
    api_bind_host: str = ""
    """Address the API links bind (empty: ``bind_host``, else 127.0.0.1 when ``[gateway]
    api_host`` (or ``host``) is on loopback, else 0.0.0.0)."""
    gcs_bind_port: Port = 0
    """Local port of the shared GCS link (0: any free port; PX4 SITL uses 18570): set it when a
    remote GCS should connect to the gateway."""
    api_bind_port_base: Port = 0
    """Local port of vehicle i's API link is this + i (0: any)."""
    api_links: bool = True
    """The per-vehicle API links (ports ``[gateway] api_port_base`` + i)."""
    signed_links: Literal["all", "gcs", "api", "none"] = "all"
    """Which links require MAVLink 2 signing when the scenario has a key."""
    cmd_timeout_s: Annotated[float, msgspec.Meta(ge=0.01, le=60.0)] = 1.5
    """How long a command waits for the autopilot's reply (MAVSDK gives up after 3 x 0.5 s,
    QGC after about 3 s)."""
    signing_state: str = ""
    """File that keeps each signed stream's newest timestamp across restarts, so a frame
    accepted before a restart is refused after it (empty: in memory only; ``plumeswarm up``
    gives ``<run dir>/mavlink-signing.state``)."""
    refuse_broadcast_disarm: bool = False
    """Answer a force disarm to every system (target_system 0) with DENIED (default:
    ``[gateway] refuse_broadcast_disarm``); it is logged either way."""

    @classmethod
    def defaults(cls, scenario: Scenario) -> Self:
        return cls(
            telemetry_hz=scenario.gateway.telemetry_hz,
            refuse_broadcast_disarm=scenario.gateway.refuse_broadcast_disarm,
        )

    def rates_hz(self) -> dict[int, float]:
        """Every telemetry stream's rate, or :class:`OptionError` for a bad ``rate.<MESSAGE>``."""
        return stream_rates(self.telemetry_hz, self.rate)

    def bind_host_for(self, section: GatewaySpec, link_kind: str) -> str:
        """The address a link of ``link_kind`` (``gcs``, ``api``) binds."""
        own = self.gcs_bind_host if link_kind == "gcs" else self.api_bind_host
        peer = peer_host(section, link_kind)
        return own or self.bind_host or ("127.0.0.1" if _is_loopback(peer) else "0.0.0.0")

    def signs(self, link_kind: str) -> bool:
        """Whether a link of ``link_kind`` (``gcs``, ``api``) requires signing given a key."""
        return self.signed_links in ("all", link_kind)


def peer_host(section: GatewaySpec, link_kind: str) -> str:
    """Where a link of ``link_kind`` sends before anyone talked to it."""
    return section.host if link_kind == "gcs" else (section.api_host or section.host)


def unsigned_exposed(section: GatewaySpec, o: GatewayOptions) -> list[str]:
    """The links that would bind beyond loopback without signing, as ``<link> on <address>``
    (:class:`OptionError` for a bad key file)."""
    key = signing_key(section)
    kinds = ["gcs", "api"] if o.api_links else ["gcs"]
    out = []
    for kind in kinds:
        bind = o.bind_host_for(section, kind)
        if not _is_loopback(bind) and not (key is not None and o.signs(kind)):
            out.append(f"{kind} link on {bind}")
    return out


def exposure_note(exposed: list[str]) -> str:
    """One line about unsigned links beyond loopback."""
    return (
        f"MAVLink without signing beyond loopback ({', '.join(exposed)}): anyone who reaches "
        "it can command the vehicles; set [gateway] signing_key_file, or bind to 127.0.0.1"
    )


def stream_rates(telemetry_hz: float, overrides: Mapping[str, float]) -> dict[int, float]:
    """Every telemetry stream's rate (MAVLink message id → Hz), ``rate.<MESSAGE>`` applied."""
    rates = default_rates(telemetry_hz)
    for name, hz in overrides.items():
        msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name.upper()}", None)
        if not isinstance(msg_id, int):
            raise OptionError(f"--set rate.{name}={hz:g}: unknown MAVLink message {name!r}")
        if msg_id not in rates:
            raise OptionError(f"--set rate.{name}={hz:g}: {name} is not a telemetry stream")
        rates[msg_id] = hz
    return rates


_KEY_HEX = re.compile(r"[0-9a-fA-F]{64}")


def signing_key(section: GatewaySpec) -> bytes | None:
    """The 32-byte signing key of ``[gateway]`` (None: signing off), or :class:`OptionError`."""
    if section.signing_key_hex and section.signing_key_file:
        raise OptionError("[gateway]: give signing_key_file or signing_key_hex, not both")
    if section.signing_key_hex:
        return bytes.fromhex(section.signing_key_hex)
    if section.signing_key_file:
        return read_key_file(Path(section.signing_key_file).expanduser())
    return None


def read_key_file(path: Path) -> bytes:
    """A key file's 32 bytes: 64 hex digits, the file private to its owner (like ssh keys)."""
    try:
        mode = path.stat().st_mode
        if not stat.S_ISREG(mode):
            raise OptionError(f"signing key file {path}: not a regular file")
        if mode & 0o077:
            raise OptionError(
                f"signing key file {path}: group/others may access it "
                f"(mode {stat.S_IMODE(mode):04o}); run chmod 600 {path}"
            )
        text = path.read_text(encoding="ascii").strip()
    except FileNotFoundError:
        raise OptionError(f"signing key file {path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise OptionError(f"signing key file {path}: cannot read it ({exc})") from None
    if not _KEY_HEX.fullmatch(text):
        raise OptionError(f"signing key file {path}: expected 64 hex digits (32 bytes)")
    return bytes.fromhex(text)


def _is_loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"
