"""UDP links: garbage never gets through or breaks parsing; signing refuses what it must."""

from __future__ import annotations

import logging
import select
import socket
import time
from collections.abc import Iterator

import pytest

from gcs_bridge.dialect import mavlink, new_mav, pack
from gcs_bridge.links import Link, Signing, signing_timestamp_now

KEY = bytes(range(32))


def heartbeat() -> object:
    return mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 0, 3)


def client_mav(key: bytes | None = None, stamp: int | None = None, system: int = 255) -> object:
    mav = new_mav(system, 190)
    if key is not None:
        mav.signing.secret_key = key
        mav.signing.link_id = 7
        mav.signing.timestamp = stamp if stamp is not None else signing_timestamp_now()
        mav.signing.sign_outgoing = True
    return mav


@pytest.fixture
def pair() -> Iterator[tuple[socket.socket, Link, Link]]:
    plain = Link("plain", ("127.0.0.1", 0), None, [1])
    signed = Link("signed", ("127.0.0.1", 0), None, [1], Signing(KEY))
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    yield sock, plain, signed
    sock.close()
    plain.close()
    signed.close()


def exchange(sock: socket.socket, link: Link, datagrams: list[bytes]) -> list[str]:
    for d in datagrams:
        sock.sendto(d, link.address)
    got: list[str] = []
    deadline = time.monotonic() + 5.0
    while link.stats.datagrams < len(datagrams):
        assert time.monotonic() < deadline, f"only {link.stats.datagrams} datagrams arrived"
        select.select([link.sock], [], [], 0.05)
        got += [m.get_type() for m, _ in link.receive(time.monotonic())]
    return got


def test_garbage_and_bad_crc_are_dropped_and_good_frames_still_parse(
    pair: tuple[socket.socket, Link, Link],
) -> None:
    sock, plain, _ = pair
    good = pack(client_mav(), heartbeat())
    bad_crc = bytearray(good)
    bad_crc[-1] ^= 0xFF
    truncated = good[:7]
    got = exchange(sock, plain, [b"\xfd\x09garbage", bytes(bad_crc), truncated, good])
    assert got == ["HEARTBEAT"]
    assert plain.stats.bad_frames >= 3


def test_signing_accepts_signed_frames_and_refuses_unsigned_wrong_key_and_replays(
    pair: tuple[socket.socket, Link, Link],
) -> None:
    sock, _, signed = pair
    good = pack(client_mav(KEY), heartbeat())
    unsigned = pack(client_mav(), heartbeat())
    wrong = pack(client_mav(bytes(32)), heartbeat())
    stale = pack(client_mav(KEY, stamp=signing_timestamp_now() - 10 * 60 * 100_000), heartbeat())
    got = exchange(sock, signed, [unsigned, wrong, good, good, stale])
    assert got == ["HEARTBEAT"]
    assert signed.stats.refused_unsigned == 1
    assert signed.stats.refused_bad_signature == 3  # wrong key, replay, stale new stream


def test_a_sender_clock_behind_by_more_than_a_minute_is_refused_with_one_warning(
    pair: tuple[socket.socket, Link, Link], caplog: pytest.LogCaptureFixture
) -> None:
    """MAVLink's window for a new signed stream is one minute: a station whose clock is 30 s
    behind the gateway's is taken, one 90 s behind refused, named once in a warning."""
    sock, _, signed = pair
    minute = 60 * 100_000
    behind_30 = client_mav(KEY, stamp=signing_timestamp_now() - minute // 2)
    behind_90 = client_mav(KEY, stamp=signing_timestamp_now() - minute * 3 // 2, system=254)
    with caplog.at_level(logging.WARNING, "gcs_bridge.links"):
        frames = [pack(behind_30, heartbeat())] + [pack(behind_90, heartbeat()) for _ in range(3)]
        got = exchange(sock, signed, frames)
    assert got == ["HEARTBEAT"]
    assert signed.stats.refused_bad_signature == 3
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1, warnings
    assert "system 254" in warnings[0] and "90 s behind this host's clock" in warnings[0]


def test_forged_frame_cannot_poison_a_stream_timestamp(
    pair: tuple[socket.socket, Link, Link],
) -> None:
    sock, _, signed = pair
    future = signing_timestamp_now() + 10**9
    forged = pack(client_mav(bytes(32), stamp=future), heartbeat())  # same stream, wrong key
    forged = forged[:-13] + bytes([7]) + forged[-12:]  # claim the legitimate link id
    good = pack(client_mav(KEY), heartbeat())
    assert exchange(sock, signed, [forged, good]) == ["HEARTBEAT"]


def test_outgoing_frames_are_mavlink2_from_component_1_and_signed_when_on(
    pair: tuple[socket.socket, Link, Link],
) -> None:
    sock, plain, signed = pair
    for link, flag in ((plain, 0), (signed, 1)):
        link.send(1, heartbeat(), time.monotonic(), to=sock.getsockname())
        data, _ = sock.recvfrom(1024)
        assert data[0] == 0xFD and data[2] & 0x01 == flag
        assert data[5] == 1 and data[6] == 1  # sysid 1, component 1


def test_peers_are_capped_and_the_quietest_goes_first(
    pair: tuple[socket.socket, Link, Link],
) -> None:
    from gcs_bridge.links import MAX_PEERS

    _, plain, _ = pair
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(MAX_PEERS + 3)]
    try:
        frame = pack(client_mav(), heartbeat())
        for i, s in enumerate(socks):
            s.bind(("127.0.0.1", 0))
            s.sendto(frame, plain.address)
            deadline = time.monotonic() + 5.0
            while plain.stats.datagrams < i + 1:
                assert time.monotonic() < deadline
                select.select([plain.sock], [], [], 0.05)
                plain.receive(i * 0.01)  # peer i last heard at "time" i / 100
        dests = plain.destinations(1.0)
        assert len(dests) == MAX_PEERS
        assert socks[-1].getsockname() in dests and socks[0].getsockname() not in dests
    finally:
        for s in socks:
            s.close()
