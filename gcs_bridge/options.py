"""The gateway's configuration: the scenario's ``[gateway]`` section plus ``--set`` options.

Options (``plumeswarm node gateway --set KEY=VALUE``):

- ``telemetry_hz``: default rate of the fast telemetry streams (per sim second);
- ``rate.<MESSAGE>``: default rate of one stream, e.g. ``rate.ATTITUDE=10`` (0 turns it off);
- ``bind_host``: address the UDP sockets bind (default: 127.0.0.1 when the GCS host is on
  loopback, else 0.0.0.0);
- ``gcs_bind_port``: local port of the shared GCS link (default 0: any free port; PX4 SITL uses
  18570) — set it when a remote GCS should connect to the gateway;
- ``api_bind_port_base``: local port of vehicle i's API link is this + i (default 0: any);
- ``api_links``: ``on`` / ``off`` (default on): the per-vehicle API ports 14540 + i;
- ``signed_links``: which links require MAVLink 2 signing when the scenario has a key:
  ``all`` (default), ``gcs``, ``api`` or ``none``;
- ``cmd_timeout_s``: how long a command waits for the autopilot's reply (default 1.5; MAVSDK
  gives up after 3 × 0.5 s, QGC after about 3 s).

The MAVLink 2 signing key comes from the scenario: ``[gateway] signing_key_file`` (a file
holding 64 hex digits, readable by its owner only — the gateway refuses a key file that group
or others may read or write) or, for tests, ``signing_key_hex`` inline.
"""

from __future__ import annotations

import ipaddress
import re
import stat
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Literal

import msgspec

from gcs_bridge.dialect import mavlink
from gcs_bridge.telemetry import default_rates
from swarmbus.options import OptionError, RoleOptions, parse_options
from swarmbus.scenario import Gateway

Port = Annotated[int, msgspec.Meta(ge=0, le=65535)]


class GatewaySettings(RoleOptions, frozen=True, kw_only=True):
    """The gateway role's options as given (``--set KEY=VALUE``); see the module docstring."""

    telemetry_hz: Annotated[float, msgspec.Meta(ge=0.01, le=1000.0)] = 4.0  # [gateway]'s
    rate: dict[str, Annotated[float, msgspec.Meta(ge=0.0, le=1000.0)]] = msgspec.field(
        default_factory=dict
    )
    bind_host: str = ""  # empty: from the GCS host (loopback or not)
    gcs_bind_port: Port = 0
    api_bind_port_base: Port = 0
    api_links: bool = True
    signed_links: Literal["all", "gcs", "api", "none"] = "all"
    cmd_timeout_s: Annotated[float, msgspec.Meta(ge=0.01, le=60.0)] = 1.5


_SIGNED = {"all": {"gcs", "api"}, "gcs": {"gcs"}, "api": {"api"}, "none": set[str]()}


@dataclass(frozen=True)
class GatewayOptions:
    host: str
    gcs_port: int
    api_port_base: int
    bind_host: str
    gcs_bind_port: int = 0
    api_bind_port_base: int = 0
    api_links: bool = True
    signing_key: bytes | None = None
    signed_links: frozenset[str] = frozenset({"gcs", "api"})
    cmd_timeout_s: float = 1.5
    rates_hz: dict[int, float] = field(default_factory=dict)
    heartbeat_period_s: float = 1.0

    def signing_key_for(self, link_kind: str) -> bytes | None:
        return self.signing_key if link_kind in self.signed_links else None


def gateway_options(section: Gateway, settings: Mapping[str, str]) -> GatewayOptions:
    """The scenario's ``[gateway]`` with ``settings`` over it, or :class:`OptionError`."""
    given = parse_options(
        GatewaySettings, settings, GatewaySettings(telemetry_hz=section.telemetry_hz)
    )
    default_bind = "127.0.0.1" if _is_loopback(section.host) else "0.0.0.0"
    return GatewayOptions(
        host=section.host,
        gcs_port=section.gcs_port,
        api_port_base=section.api_port_base,
        bind_host=given.bind_host or default_bind,
        gcs_bind_port=given.gcs_bind_port,
        api_bind_port_base=given.api_bind_port_base,
        api_links=given.api_links,
        signing_key=signing_key(section),
        signed_links=frozenset(_SIGNED[given.signed_links]),
        cmd_timeout_s=given.cmd_timeout_s,
        rates_hz=stream_rates(given.telemetry_hz, given.rate),
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


def signing_key(section: Gateway) -> bytes | None:
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
