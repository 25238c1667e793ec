"""A raw MAVLink 2 ground station for tests (pymavlink framing, our own socket), and helpers
to run the gateway against a scenario with test ports.

The client listens like QGC does (``udpin``): the gateway sends to its port, and the client
answers to whatever address the gateway's packets came from, per vehicle sysid.
"""

from __future__ import annotations

import asyncio
import collections
import math
import select
import socket
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from gcs_bridge.dialect import mavlink, new_mav, pack
from gcs_bridge.links import signing_timestamp_now
from swarmbus.closeable import Closeable
from swarmbus.session import free_udp_block
from tests.support.procs import REPO

Msg = Any
# The telemetry a PX4-like vehicle streams (docs/qgroundcontrol.md, "Telemetry rates"): the fast
# streams at [gateway] telemetry_hz, the slow ones at fixed rates (Hz of sim time).
FAST_STREAMS = (
    "SYS_STATUS",
    "GPS_RAW_INT",
    "GLOBAL_POSITION_INT",
    "ATTITUDE",
    "VFR_HUD",
    "EXTENDED_SYS_STATE",
    "NAMED_VALUE_FLOAT",
)
SLOW_STREAMS_HZ = {"BATTERY_STATUS": 1.0, "MISSION_CURRENT": 1.0, "HOME_POSITION": 0.5}

GCS_SYSID = 255
GCS_COMPID = 190


def scenario_text(
    vehicles: int,
    gcs_port: int,
    api_base: int,
    signing_key_hex: str | None = None,
    telemetry_hz: float = 4.0,
    signing_key_file: Path | None = None,
) -> str:
    """The novak2018 scenario with test ports and ``vehicles`` Iris quads in a row."""
    base = (REPO / "swarmbus" / "scenarios" / "novak2018.toml").read_text()
    head = base.split("[gateway]")[0]
    lines = [
        head,
        "[gateway]",
        'host = "127.0.0.1"',
        f"gcs_port = {gcs_port}",
        f"api_port_base = {api_base}",
        f"telemetry_hz = {telemetry_hz}",
    ]
    if signing_key_hex:
        lines.append(f'signing_key_hex = "{signing_key_hex}"')
    if signing_key_file:
        lines.append(f'signing_key_file = "{signing_key_file}"')
    for i in range(vehicles):
        y = 4.0 * i - 2.0 * (vehicles - 1)
        lines += [
            "",
            "[[vehicles]]",
            f'id = "uav{i + 1}"',
            'type = "iris"',
            f"sysid = {i + 1}",
            f"spawn_enu_m = [20.0, {y}, 0.0]",
            "mission = [",
            f'  {{ command = "takeoff", x = 20.0, y = {y}, z = 10.0 }},',
            f"  {{ x = 30.0, y = {y}, z = 10.0 }},",
            f"  {{ x = 30.0, y = {y + 2.0}, z = 10.0 }},",
            f'  {{ command = "land", x = 30.0, y = {y + 2.0}, z = 0.0 }},',
            "]",
        ]
    return "\n".join(lines) + "\n"


async def first(gen: Any, pred: Any, what: str, timeout_s: float = 120.0) -> Any:
    """The first value of an async stream (a MAVSDK subscription) that satisfies ``pred``."""

    async def scan() -> Any:
        async for value in gen:
            if pred(value):
                return value
        raise AssertionError(f"stream ended before {what}")

    try:
        return await asyncio.wait_for(scan(), timeout_s)
    except TimeoutError:
        raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}") from None


def write_scenario(path: Path, vehicles: int, **kw: Any) -> tuple[Path, int, int]:
    """Write a test scenario; returns (path, gcs_port, api_base)."""
    gcs = free_udp_block(1)
    api = free_udp_block(vehicles)
    path.write_text(scenario_text(vehicles, gcs, api, **kw))
    return path, gcs, api


def heard_all(seen: set[int], n: int, msg: Msg) -> bool:
    """A ``MavClient.wait`` predicate: heartbeats from ``n`` systems (noted in ``seen``)."""
    if msg.get_type() == "HEARTBEAT":
        seen.add(msg.get_srcSystem())
    return len(seen) == n


class MavClient(Closeable):
    """A listening MAVLink 2 endpoint that talks to every vehicle it hears."""

    def __init__(
        self,
        port: int,
        system: int = GCS_SYSID,
        component: int = GCS_COMPID,
        signing_key: bytes | None = None,
    ) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        # a big receive buffer: 16 vehicles' telemetry comes in bursts and this test process
        # may be descheduled for a while on a busy machine
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 8 << 20)
        self.sock.bind(("127.0.0.1", port))
        self.sock.setblocking(False)
        self.mav = new_mav(system, component)
        if signing_key is not None:
            self.mav.signing.secret_key = signing_key
            self.mav.signing.link_id = 1
            self.mav.signing.timestamp = signing_timestamp_now()
            self.mav.signing.sign_outgoing = True
        self.addr_of: dict[int, tuple[str, int]] = {}
        self.beat = False  # send a GCS HEARTBEAT once per second while pumping, as QGC does
        self._last_beat = 0.0
        self.inbox: collections.deque[Msg] = collections.deque()
        self.log: list[Msg] = []  # everything received, in order

    def close(self) -> None:
        self.sock.close()

    # -- raw I/O -------------------------------------------------------------------
    def pump(self, timeout_s: float = 0.05) -> None:
        if self.beat and self.addr_of and time.monotonic() - self._last_beat >= 1.0:
            self._last_beat = time.monotonic()
            self.heartbeat()
        select.select([self.sock], [], [], timeout_s)
        while True:
            try:
                data, addr = self.sock.recvfrom(65535)
            except BlockingIOError:
                return
            parser = new_mav(0, 0)
            for m in parser.parse_buffer(data) or []:
                if m.get_type() in ("BAD_DATA", "UNKNOWN"):
                    continue
                self.addr_of[m.get_srcSystem()] = addr
                self.inbox.append(m)
                self.log.append(m)

    def send(self, sysid: int, msg: Msg) -> None:
        self.send_raw(sysid, pack(self.mav, msg))

    def send_raw(self, sysid: int, data: bytes) -> None:
        addr = self.addr_of.get(sysid) or next(iter(self.addr_of.values()))
        self.sock.sendto(data, addr)

    # -- waiting -------------------------------------------------------------------
    def wait(
        self,
        what: str,
        pred: Callable[[Msg], bool],
        timeout_s: float = 60.0,
    ) -> Msg:
        """The first message (new or queued) matching ``pred``; fail naming ``what``."""
        deadline = time.monotonic() + timeout_s
        while True:
            while self.inbox:
                m = self.inbox.popleft()
                if pred(m):
                    return m
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"timed out after {timeout_s:.0f} s waiting for {what}\n{self.last_words()}"
                )
            self.pump()

    def last_words(self) -> str:
        """What the vehicles said last (heartbeat mode, STATUSTEXTs): CI shows only the tail."""
        lines = []
        for sysid in sorted(self.addr_of):
            hb = next(
                (
                    m
                    for m in reversed(self.log)
                    if m.get_type() == "HEARTBEAT" and m.get_srcSystem() == sysid
                ),
                None,
            )
            if hb is not None:
                lines.append(
                    f"  sysid {sysid}: custom_mode {hb.custom_mode:#x} base_mode {hb.base_mode:#x}"
                    f" status {hb.system_status}"
                )
            texts = [m.text for m in self.logged("STATUSTEXT", sysid)][-5:]
            lines.extend(f"  sysid {sysid} said: {t}" for t in texts)
        return "last heard:\n" + "\n".join(lines)

    def until(self, what: str, cond: Callable[[], bool], timeout_s: float = 60.0) -> None:
        """Pump until ``cond()`` holds (it may look at ``self.log``, which keeps everything)."""
        deadline = time.monotonic() + timeout_s
        while not cond():
            if time.monotonic() > deadline:
                raise AssertionError(
                    f"timed out after {timeout_s:.0f} s waiting for {what}\n{self.last_words()}"
                )
            self.pump()

    def logged(self, kind: str, sysid: int) -> list[Msg]:
        return [m for m in self.log if m.get_type() == kind and m.get_srcSystem() == sysid]

    def wait_standby(self, sysid: int, timeout_s: float = 120.0) -> Msg:
        """A HEARTBEAT of ``sysid`` saying MAV_STATE_STANDBY (its autopilot's status arrived)."""
        return self.wait_type(
            "HEARTBEAT", sysid, timeout_s, system_status=mavlink.MAV_STATE_STANDBY
        )

    def wait_type(self, kind: str, sysid: int, timeout_s: float = 60.0, **fields: Any) -> Msg:
        def match(m: Msg) -> bool:
            return (
                m.get_type() == kind
                and m.get_srcSystem() == sysid
                and all(getattr(m, k) == v for k, v in fields.items())
            )

        return self.wait(f"{kind} {fields} from sysid {sysid}", match, timeout_s)

    def collect(self, seconds: float) -> list[Msg]:
        """Everything that arrives in the next ``seconds`` (for counting, never for timing)."""
        self.inbox.clear()
        end = time.monotonic() + seconds
        out: list[Msg] = []
        while time.monotonic() < end:
            self.pump()
            out.extend(self.inbox)
            self.inbox.clear()
        return out

    def drain(self) -> None:
        self.pump(0.0)
        self.inbox.clear()

    # -- protocol helpers ------------------------------------------------------------
    def heartbeat(self) -> None:
        hb = mavlink.MAVLink_heartbeat_message(
            mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3
        )
        for sysid in list(self.addr_of):
            self.send(sysid, hb)

    def command(self, sysid: int, command: int, *params: float, timeout_s: float = 30.0) -> int:
        """COMMAND_LONG and its COMMAND_ACK result."""
        p = [*params, *([0.0] * (7 - len(params)))]
        self.send(
            sysid,
            mavlink.MAVLink_command_long_message(sysid, 1, command, 0, *p),
        )
        ack = self.wait_type("COMMAND_ACK", sysid, timeout_s, command=command)
        assert ack.target_system == GCS_SYSID
        return int(ack.result)

    def set_mode(self, sysid: int, main: int, sub: int = 0) -> None:
        custom = (main << 16) | (sub << 24)
        self.send(
            sysid,
            mavlink.MAVLink_set_mode_message(
                sysid, mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, custom
            ),
        )

    def wait_mode(
        self, sysid: int, main: int, sub: int, armed: bool | None = None, timeout_s: float = 60.0
    ) -> Msg:
        custom = (main << 16) | (sub << 24)

        def match(m: Msg) -> bool:
            if m.get_type() != "HEARTBEAT" or m.get_srcSystem() != sysid:
                return False
            is_armed = bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
            return m.custom_mode == custom and (armed is None or armed == is_armed)

        return self.wait(
            f"heartbeat of {sysid} in mode {main}/{sub} armed={armed}", match, timeout_s
        )

    def wait_armed(self, sysid: int, armed: bool = True, timeout_s: float = 60.0) -> None:
        """Until a HEARTBEAT of ``sysid`` says it is armed (or, ``armed=False``, disarmed)."""
        self.wait(
            f"sysid {sysid} {'armed' if armed else 'disarmed'}",
            lambda m: (
                m.get_type() == "HEARTBEAT"
                and m.get_srcSystem() == sysid
                and bool(m.base_mode & mavlink.MAV_MODE_FLAG_SAFETY_ARMED) == armed
            ),
            timeout_s,
        )

    def wait_disarmed(self, sysid: int, timeout_s: float = 60.0) -> None:
        self.wait_armed(sysid, False, timeout_s)

    def wait_above(self, sysid: int, metres: float, timeout_s: float = 120.0) -> None:
        """Until ``sysid`` reports a relative altitude above ``metres``."""
        self.wait(
            f"sysid {sysid} above {metres} m",
            lambda m: (
                m.get_type() == "GLOBAL_POSITION_INT"
                and m.get_srcSystem() == sysid
                and m.relative_alt > metres * 1000
            ),
            timeout_s,
        )

    def params(self, sysid: int, timeout_s: float = 60.0) -> dict[str, tuple[float, int, int, int]]:
        """PARAM_REQUEST_LIST → {name: (value, type, count, index)}."""
        self.send(sysid, mavlink.MAVLink_param_request_list_message(sysid, 1))
        out: dict[str, tuple[float, int, int, int]] = {}
        first = self.wait_type("PARAM_VALUE", sysid, timeout_s)
        out[_name(first.param_id)] = _param(first)
        while len(out) < first.param_count:
            m = self.wait_type("PARAM_VALUE", sysid, timeout_s)
            out[_name(m.param_id)] = _param(m)
        return out

    def param_set(self, sysid: int, name: str, value: float, ptype: int) -> Msg:
        self.send(sysid, mavlink.MAVLink_param_set_message(sysid, 1, name.encode(), value, ptype))
        return self.wait(
            f"PARAM_VALUE {name}",
            lambda m: (
                m.get_type() == "PARAM_VALUE"
                and m.get_srcSystem() == sysid
                and _name(m.param_id) == name
            ),
        )

    def upload(self, sysid: int, items: list[Msg], mission_type: int = 0) -> int:
        """MISSION_COUNT → answer every MISSION_REQUEST_INT → the final MISSION_ACK type."""
        self.send(sysid, mavlink.MAVLink_mission_count_message(sysid, 1, len(items), mission_type))
        while True:
            m = self.wait(
                "MISSION_REQUEST_INT or MISSION_ACK",
                lambda m: (
                    m.get_srcSystem() == sysid
                    and m.get_type() in ("MISSION_REQUEST_INT", "MISSION_ACK")
                ),
            )
            if m.get_type() == "MISSION_ACK":
                return int(m.type)
            self.send(sysid, items[m.seq])

    def download(self, sysid: int) -> list[Msg]:
        self.send(sysid, mavlink.MAVLink_mission_request_list_message(sysid, 1, 0))
        count = self.wait_type("MISSION_COUNT", sysid).count
        items = []
        for seq in range(count):
            self.send(sysid, mavlink.MAVLink_mission_request_int_message(sysid, 1, seq, 0))
            items.append(self.wait_type("MISSION_ITEM_INT", sysid, seq=seq))
        self.send(sysid, mavlink.MAVLink_mission_ack_message(sysid, 1, 0, 0))
        return items


def mission_item(
    sysid: int, seq: int, command: int, lat: float, lon: float, rel_alt: float, param1: float = 0.0
) -> Msg:
    return mavlink.MAVLink_mission_item_int_message(
        sysid,
        1,
        seq,
        mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
        command,
        0,
        1,
        param1,
        0.0,
        0.0,
        math.nan,
        round(lat * 1e7),
        round(lon * 1e7),
        rel_alt,
        0,
    )


def _name(raw: Any) -> str:
    if isinstance(raw, bytes):
        return raw.split(b"\0", 1)[0].decode()
    return str(raw).split("\0", 1)[0]


def _param(m: Msg) -> tuple[float, int, int, int]:
    return (float(m.param_value), int(m.param_type), int(m.param_count), int(m.param_index))


@contextmanager
def clients(*ports: int, **kw: Any) -> Iterator[list[MavClient]]:
    cs = [MavClient(p, **kw) for p in ports]
    try:
        yield cs
    finally:
        for c in cs:
            c.close()


TIMESTAMPED = {"ATTITUDE", "GLOBAL_POSITION_INT", "LOCAL_POSITION_NED", "NAMED_VALUE_FLOAT"}


@dataclass
class RateWindow:
    """What ``measure_rates`` heard of each vehicle inside its window of sim time."""

    sim_seconds: float
    seen: dict[int, list[Any]]
    first: dict[int, int] = field(default_factory=dict)  # ATTITUDE time_boot_ms
    last: dict[int, int] = field(default_factory=dict)

    def full(self, s: int) -> bool:
        return s in self.last and self.last[s] - self.first[s] >= self.sim_seconds * 1000

    def done(self) -> bool:
        return all(s in self.first and self.full(s) for s in self.seen)

    def take(self, m: Any) -> None:
        s = m.get_srcSystem()
        if s not in self.seen:
            return
        if m.get_type() == "ATTITUDE":
            self.first.setdefault(s, m.time_boot_ms)
            if not self.full(s):
                self.last[s] = m.time_boot_ms
        if s in self.first and not self.full(s):
            self.seen[s].append(m)


def rates_of(msgs: list[Any], span_s: float) -> dict[str, float]:
    """Messages per second by type: timestamped ones over their own span, others over ``span_s``."""
    counts: dict[str, list[Any]] = collections.defaultdict(list)
    for m in msgs:
        counts[m.get_type()].append(m)
    out: dict[str, float] = {}
    for kind, ms in counts.items():
        if kind in TIMESTAMPED and len(ms) > 1:
            t = [m.time_boot_ms for m in ms]
            out[kind] = (len(ms) - 1) / max((max(t) - min(t)) / 1000.0, 1e-9)
        else:
            out[kind] = len(ms) / span_s
    return out


def measure_rates(
    c: MavClient, sysids: list[int], sim_seconds: float, timeout_s: float
) -> tuple[dict[int, dict[str, float]], float]:
    """Messages per simulated second, per vehicle and type, over ``sim_seconds`` of each
    vehicle's sim time (ATTITUDE's time_boot_ms is the clock); and the wall seconds it took.

    Types without a timestamp are counted between the vehicle's first and last ATTITUDE.
    """
    c.drain()
    start = time.monotonic()
    window = RateWindow(sim_seconds, {s: [] for s in sysids})
    while not window.done():
        if time.monotonic() - start > timeout_s:
            spans = {s: (window.last.get(s, 0) - window.first.get(s, 0)) / 1000 for s in sysids}
            raise AssertionError(f"sim time did not advance {sim_seconds} s in time: {spans}")
        c.pump()
        while c.inbox:
            window.take(c.inbox.popleft())
    wall = time.monotonic() - start
    rates = {
        s: rates_of(msgs, (window.last[s] - window.first[s]) / 1000.0)
        for s, msgs in window.seen.items()
    }
    return rates, wall
