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
import math
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path

from gcs_bridge.dialect import mavlink
from gcs_bridge.telemetry import default_rates
from swarmbus.scenario import Gateway

KNOWN = {
    "telemetry_hz",
    "bind_host",
    "gcs_bind_port",
    "api_bind_port_base",
    "api_links",
    "signed_links",
    "cmd_timeout_s",
}


class OptionError(ValueError):
    pass


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


def _float(key: str, text: str, lo: float, hi: float) -> float:
    try:
        value = float(text)
    except ValueError:
        raise OptionError(f"--set {key}: expected a number, got {text!r}") from None
    if not math.isfinite(value) or not lo <= value <= hi:
        raise OptionError(f"--set {key}: must be within [{lo:g}, {hi:g}], got {text!r}")
    return value


def _port(key: str, text: str) -> int:
    value = _float(key, text, 0, 65535)
    if value != int(value):
        raise OptionError(f"--set {key}: expected a port number, got {text!r}")
    return int(value)


def _switch(key: str, text: str) -> bool:
    if text.lower() in ("on", "true", "1", "yes"):
        return True
    if text.lower() in ("off", "false", "0", "no"):
        return False
    raise OptionError(f"--set {key}: expected on or off, got {text!r}")


def _message_id(key: str) -> int:
    name = key.removeprefix("rate.").upper()
    msg_id = getattr(mavlink, f"MAVLINK_MSG_ID_{name}", None)
    if not isinstance(msg_id, int):
        raise OptionError(f"--set {key}: unknown MAVLink message {name!r}")
    return msg_id


def parse_options(section: Gateway, options: dict[str, str]) -> GatewayOptions:
    """Validated options, or :class:`OptionError` naming the bad one."""
    loopback = _is_loopback(section.host)
    values: dict[str, object] = {}
    telemetry_hz = section.telemetry_hz
    rate_overrides: dict[int, float] = {}
    for key, text in options.items():
        if key.startswith("rate."):
            rate_overrides[_message_id(key)] = _float(key, text, 0.0, 1000.0)
        elif key not in KNOWN:
            raise OptionError(
                f"unknown gateway option {key!r}; known: {', '.join(sorted(KNOWN))}, rate.<MSG>"
            )
        elif key == "telemetry_hz":
            telemetry_hz = _float(key, text, 0.01, 1000.0)
        elif key == "bind_host":
            values[key] = text
        elif key in ("gcs_bind_port", "api_bind_port_base"):
            values[key] = _port(key, text)
        elif key == "api_links":
            values[key] = _switch(key, text)
        elif key == "cmd_timeout_s":
            values[key] = _float(key, text, 0.01, 60.0)
        elif key == "signed_links":
            choice = {"all": {"gcs", "api"}, "gcs": {"gcs"}, "api": {"api"}, "none": set()}
            if text not in choice:
                raise OptionError(f"--set {key}: expected all, gcs, api or none, got {text!r}")
            values[key] = frozenset(choice[text])
    rates = default_rates(telemetry_hz)
    for msg_id, hz in rate_overrides.items():
        if msg_id not in rates:
            raise OptionError(f"--set rate.*: message {msg_id} is not a telemetry stream")
        rates[msg_id] = hz
    return GatewayOptions(
        host=section.host,
        gcs_port=section.gcs_port,
        api_port_base=section.api_port_base,
        bind_host=str(values.pop("bind_host", "127.0.0.1" if loopback else "0.0.0.0")),
        signing_key=signing_key(section),
        rates_hz=rates,
        **values,  # type: ignore[arg-type]
    )


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
