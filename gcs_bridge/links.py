"""UDP links (:class:`Link`, :class:`LinkSet`): one socket each, the peers heard on it, MAVLink 2
framing, signing (the signature is checked before a stream's timestamp is recorded, so a forged
frame cannot push it forward) and who listens (``IP_RECVERR``). See docs/qgroundcontrol.md
("Signing", "Telemetry rates").
"""

from __future__ import annotations

import errno
import hashlib
import logging
import math
import os
import socket
import struct
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from gcs_bridge.dialect import Msg, new_mav, pack
from gcs_bridge.telemetry import StreamSchedule

log = logging.getLogger(__name__)

Addr = tuple[str, int]
SIGNATURE_LEN = 13  # link id (1) + timestamp (6) + signature (6)
_EPOCH_2015 = 1420070400
_NEW_STREAM_WINDOW = 60 * 100_000  # one minute, in 10 µs units
_RECORD = struct.Struct("<BBB5xQ")  # a stream's link id, system, component; its newest stamp
PEER_EXPIRY_S = 15.0
MAX_PEERS = 16  # per link: one datagram must not buy a stranger our telemetry stream forever
MAX_DATAGRAMS_PER_POLL = 256
SEND_ATTEMPTS = 8  # a send refused for earlier datagrams' ICMP errors is tried again
REFUSED_HOLD_S = 2.5  # > the heartbeat period: heartbeats keep an absent listener's mark fresh
IP_RECVERR = getattr(socket, "IP_RECVERR", 11)  # Linux's value; Python does not export it
_NOBODY_THERE = {errno.ECONNREFUSED, errno.EHOSTUNREACH, errno.ENETUNREACH}


def signing_timestamp_now() -> int:
    """MAVLink signing time: 10 µs units since 2015-01-01."""
    return int(max(time.time() - _EPOCH_2015, 0.0) * 100_000)


def _nobody_there(level: int, kind: int, data: bytes) -> bool:
    """Does an error-queue entry (``struct sock_extended_err``: errno first) say that nobody
    listens at the destination?"""
    return (
        level == socket.IPPROTO_IP
        and kind == IP_RECVERR
        and len(data) >= 4
        and struct.unpack_from("=I", data)[0] in _NOBODY_THERE
    )


@dataclass
class LinkStats:
    datagrams: int = 0
    received: int = 0
    bad_frames: int = 0
    refused_unsigned: int = 0
    refused_bad_signature: int = 0
    sent: int = 0
    send_errors: int = 0


class Signing:
    """The signing state of one key, shared by every link that signs with it: a stream is the
    (link id, system, component) a frame names, whichever socket it arrives on, so a frame
    accepted on one link is a replay on every other. With ``state_path`` each stream's newest
    timestamp is written to that file before the frame is handled (one fixed-size record per
    stream, written in place: a ``SIGKILL`` loses nothing the kernel was given) and read back
    at start, so a frame accepted before a restart is a replay after it."""

    def __init__(self, key: bytes, state_path: Path | None = None) -> None:
        self.key = key
        self.stream_timestamps: dict[tuple[int, int, int], int] = {}
        self._slots: dict[tuple[int, int, int], int] = {}
        self._fd: int | None = None
        self.write_errors = 0
        self._stale_warned: set[tuple[int, int, int]] = set()  # streams named in a warning
        if state_path is not None:
            self._fd = os.open(state_path, os.O_RDWR | os.O_CREAT, 0o600)
            data = os.pread(self._fd, 1 << 24, 0)
            whole = len(data) - len(data) % _RECORD.size  # a torn last record is dropped
            for slot, offset in enumerate(range(0, whole, _RECORD.size)):
                link_id, system, component, stamp = _RECORD.unpack_from(data, offset)
                stream = (link_id, system, component)
                self._slots[stream] = slot
                self.stream_timestamps[stream] = max(stamp, self.stream_timestamps.get(stream, 0))

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None

    def verify(self, msgbuf: bytes, system: int, component: int) -> str | None:
        """None if ``msgbuf`` is validly signed with our key and fresh; else why not."""
        if len(msgbuf) < 10 + 2 + SIGNATURE_LEN or msgbuf[0] != 0xFD or not msgbuf[2] & 0x01:
            return "unsigned"
        digest = hashlib.sha256(self.key + msgbuf[:-6]).digest()[:6]
        if digest != msgbuf[-6:]:
            return "bad signature"
        link_id = msgbuf[-13]
        low, high = struct.unpack("<IH", msgbuf[-12:-6])
        stamp = low + (high << 32)
        stream = (link_id, system, component)
        last = self.stream_timestamps.get(stream)
        if last is not None and stamp <= last:
            return "replayed timestamp"
        if last is None and stamp + _NEW_STREAM_WINDOW < (now := signing_timestamp_now()):
            self._warn_stale(stream, (now - stamp) / 100_000)
            return "stale timestamp"
        self.stream_timestamps[stream] = stamp
        self._persist(stream, stamp)
        return None

    def _warn_stale(self, stream: tuple[int, int, int], age_s: float) -> None:
        """Once per stream: its first frame, validly signed, is older than a new stream may be
        (the sender has the key; its clock is behind ours, or the frame is a replay). Only
        holders of the key can make streams, so the warnings are bounded."""
        if stream in self._stale_warned:
            return
        self._stale_warned.add(stream)
        link_id, system, component = stream
        log.warning(
            "refused signed frames of link id %d, system %d, component %d: their timestamp is "
            "%.0f s behind this host's clock, a new stream may be at most %.0f s behind; the "
            "sender's clock is behind (check both hosts' clocks: chronyc tracking) or the "
            "frames are a replay",
            link_id,
            system,
            component,
            age_s,
            _NEW_STREAM_WINDOW / 100_000,
        )

    def _persist(self, stream: tuple[int, int, int], stamp: int) -> None:
        if self._fd is None:
            return
        slot = self._slots.setdefault(stream, len(self._slots))
        try:
            os.pwrite(self._fd, _RECORD.pack(*stream, stamp), slot * _RECORD.size)
        except OSError as exc:
            self.write_errors += 1
            if self.write_errors == 1:
                log.error("signing timestamps: cannot write them (%s); kept in memory", exc)


class Link:
    """One UDP socket speaking MAVLink 2 for the vehicles (sysids) it serves."""

    def __init__(
        self,
        name: str,
        bind: Addr,
        default_peer: Addr | None,
        sysids: list[int],
        signing: Signing | None = None,
        link_id: int = 0,
    ) -> None:
        self.name = name
        self.default_peer = default_peer
        self.sysids = list(sysids)
        self.stats = LinkStats()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.setblocking(False)
        self.sock.bind(bind)
        self._errors_queued = sys.platform == "linux"
        if self._errors_queued:
            self.sock.setsockopt(socket.IPPROTO_IP, IP_RECVERR, 1)
        self._peers: dict[Addr, float] = {}
        self._refused: dict[Addr, float] = {}  # destination → wall time of its last refusal
        self.gcs_heard_s = -1e9  # wall time of the last ground-station HEARTBEAT on this link
        self.signing = signing
        self._encoders = {sysid: self._encoder(sysid, link_id) for sysid in self.sysids}

    def _encoder(self, sysid: int, link_id: int) -> Msg:
        mav = new_mav(sysid, 1)
        if self.signing is not None:
            mav.signing.secret_key = self.signing.key
            mav.signing.link_id = link_id
            mav.signing.timestamp = signing_timestamp_now()
            mav.signing.sign_outgoing = True
        return mav

    @property
    def address(self) -> Addr:
        host, port = self.sock.getsockname()
        return (str(host), int(port))

    def fileno(self) -> int:
        return self.sock.fileno()

    def close(self) -> None:
        self.sock.close()

    # -- receiving -------------------------------------------------------------
    def receive(self, now_s: float) -> list[tuple[Msg, Addr]]:
        """Every valid message waiting on the socket (bounded per call), with its sender."""
        self._take_refusals(now_s)
        out: list[tuple[Msg, Addr]] = []
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                data, addr = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:  # e.g. ICMP port unreachable reported on a later recv
                log.debug("%s: recv error %s", self.name, exc)
                continue
            self.stats.datagrams += 1
            peer = (str(addr[0]), int(addr[1]))
            accepted = self._parse(data, peer)
            if accepted:
                if peer not in self._peers and len(self._peers) >= MAX_PEERS:
                    del self._peers[min(self._peers, key=self._peers.__getitem__)]
                self._peers[peer] = now_s
                self._refused.pop(peer, None)
                out.extend((m, peer) for m in accepted)
        return out

    def _take_refusals(self, now_s: float) -> None:
        """Destinations the kernel reported unreachable (ICMP, queued by ``IP_RECVERR``)."""
        if not self._errors_queued:
            return
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                _, ancillary, _, addr = self.sock.recvmsg(1, 512, socket.MSG_ERRQUEUE)
            except (BlockingIOError, InterruptedError):
                return
            except OSError as exc:
                log.debug("%s: error queue: %s", self.name, exc)
                return
            if any(_nobody_there(level, kind, data) for level, kind, data in ancillary):
                self._refused[(str(addr[0]), int(addr[1]))] = now_s

    def listened(self, now_s: float) -> bool:
        """Is anyone there to receive what this link sends (see the module's docstring)?"""
        if not self._refused:
            return True
        hold = now_s - REFUSED_HOLD_S
        for addr, heard in self._peers.items():
            if now_s - heard <= PEER_EXPIRY_S and self._refused.get(addr, -math.inf) < hold:
                return True
        peer = self.default_peer
        return peer is not None and self._refused.get(peer, -math.inf) < hold

    def _parse(self, data: bytes, peer: Addr) -> list[Msg]:
        parser = new_mav(0, 0)
        try:
            msgs = parser.parse_buffer(data) or []
        except Exception as exc:  # pymavlink raises a few odd types on garbage
            self.stats.bad_frames += 1
            log.debug("%s: unparsable datagram from %s: %s", self.name, peer, exc)
            return []
        if parser.buf_len() > 0:  # a truncated frame at the end of the datagram
            self.stats.bad_frames += 1
        good: list[Msg] = []
        for m in msgs:
            kind = m.get_type()
            if kind in ("BAD_DATA", "UNKNOWN"):
                self.stats.bad_frames += 1
                continue
            if self.signing is not None:
                why = self.signing.verify(
                    bytes(m.get_msgbuf()), m.get_srcSystem(), m.get_srcComponent()
                )
                if why is not None:
                    if why == "unsigned":
                        self.stats.refused_unsigned += 1
                    else:
                        self.stats.refused_bad_signature += 1
                    log.debug("%s: refused %s from %s: %s", self.name, kind, peer, why)
                    continue
            self.stats.received += 1
            good.append(m)
        return good

    # -- sending ---------------------------------------------------------------
    def destinations(self, now_s: float) -> list[Addr]:
        for addr, heard in list(self._peers.items()):
            if now_s - heard > PEER_EXPIRY_S:
                del self._peers[addr]
        dests = list(self._peers)
        if self.default_peer is not None and self.default_peer not in self._peers:
            dests.append(self.default_peer)
        return dests

    def send(self, sysid: int, msg: Msg, now_s: float, to: Addr | None = None) -> None:
        """Send ``msg`` as vehicle ``sysid`` (component 1) to ``to``, or to every peer."""
        mav = self._encoders.get(sysid)
        if mav is None:
            return
        buf = pack(mav, msg)
        for addr in [to] if to is not None else self.destinations(now_s):
            try:
                self._sendto(buf, addr)
                self.stats.sent += 1
            except OSError as exc:
                self.stats.send_errors += 1
                log.debug("%s: send to %s failed: %s", self.name, addr, exc)

    def _sendto(self, buf: bytes, addr: Addr) -> None:
        # With IP_RECVERR an earlier datagram's ICMP error is reported by a later send call,
        # which then sends nothing and takes the error. Another error can arrive before the
        # next try (the ICMP of each datagram sent to a port where nobody listens), so try
        # until sent: a refused call never sent its datagram, so nothing goes out twice.
        for _ in range(SEND_ATTEMPTS - 1):
            try:
                self.sock.sendto(buf, addr)
                return
            except ConnectionRefusedError:
                continue
        self.sock.sendto(buf, addr)


class LinkSet:
    """Every link of the gateway: by name, and the links each vehicle (sysid) is on, with the
    telemetry schedule of each (vehicle, link) pair."""

    def __init__(
        self, rates_hz: dict[int, float], sysids: list[int], signing: Signing | None = None
    ) -> None:
        self.signing = signing  # shared by the links that sign; closed with them
        self._rates_hz = rates_hz
        self._by_name: dict[str, Link] = {}
        self._of: dict[int, list[Link]] = {sysid: [] for sysid in sysids}
        self._schedules: dict[tuple[str, int], StreamSchedule] = {}

    def add(self, link: Link) -> None:
        self._by_name[link.name] = link
        for sysid in link.sysids:
            self._of[sysid].append(link)
            self._schedules[(link.name, sysid)] = StreamSchedule(self._rates_hz)
        log.info(
            "link %s: %s:%d → %s (sysids %s, signing %s)",
            link.name,
            *link.address,
            link.default_peer,
            link.sysids,
            "on" if link.signing else "off",
        )

    def all(self) -> list[Link]:
        return list(self._by_name.values())

    def named(self, name: str) -> Link:
        return self._by_name[name]

    def of(self, sysid: int) -> list[Link]:
        """The links vehicle ``sysid`` is on."""
        return self._of[sysid]

    def schedule(self, link: Link, sysid: int) -> StreamSchedule:
        return self._schedules[(link.name, sysid)]

    def listened(self, now_s: float) -> bool:
        """Does any link have someone to send telemetry to?"""
        return any(link.listened(now_s) for link in self._by_name.values())

    def close(self) -> None:
        for link in self._by_name.values():
            link.close()
        if self.signing is not None:
            self.signing.close()
