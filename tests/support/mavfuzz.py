"""A seeded MAVLink 2 fuzzer for the gateway: hostile datagrams and the replies each must get.

Three senders: ``junk`` (random bytes, corrupted and truncated frames: nothing may come of
them), ``stranger`` (well-formed frames — valid ARM, takeoff, mode and mission commands among
them — for other systems or components, or claiming to come from one of our vehicles: all
ignored) and ``client`` (well-formed frames for our vehicles with invalid fields: each gets its
exact answer, and none reaches the autopilot). Every frame the client sends is answered by the
gateway itself, synchronously, so a batch's replies can be counted exactly.

A reply is ``(message type, vehicle sysid, a, b)``: COMMAND_ACK (command, result),
MISSION_ACK (type, 0), MISSION_REQUEST_INT (seq, 0), PARAM_VALUE (index, 0),
MESSAGE_INTERVAL (message id, 0).
"""

from __future__ import annotations

import math
import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from gcs_bridge.dialect import mavlink, new_mav, pack
from gcs_bridge.params import SPECS

Msg = Any
Reply = tuple[str, int, int, int]

CLIENT = (255, 190)
STRANGER = (254, 191)
REPLY_TYPES = {
    "COMMAND_ACK",
    "MISSION_ACK",
    "MISSION_REQUEST_INT",
    "MISSION_REQUEST",
    "MISSION_COUNT",
    "MISSION_ITEM_INT",
    "MISSION_ITEM",
    "PARAM_VALUE",
    "MESSAGE_INTERVAL",
}

NAN = math.nan
INF = math.inf
M = mavlink
DENIED = int(M.MAV_RESULT_DENIED)
TEMP_REJECTED = int(M.MAV_RESULT_TEMPORARILY_REJECTED)
UNSUPPORTED = int(M.MAV_RESULT_UNSUPPORTED)
ACCEPTED = int(M.MAV_RESULT_ACCEPTED)
REL_INT = int(M.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT)
GET_INTERVAL = int(M.MAV_CMD_GET_MESSAGE_INTERVAL)
# every command the gateway knows (anything else must be UNSUPPORTED)
KNOWN_COMMANDS = {16, 17, 20, 21, 22, 34, 176, 192, 193, 300, 400, 510, 511, 512, 519, 520}
BAD_FLOATS = (NAN, INF, -INF)
INT32_MAX = 2**31 - 1
SENTINEL_BASE = 40000  # GET_MESSAGE_INTERVAL of these ids closes a batch (not streams)


def reply_of(m: Msg) -> Reply | None:
    kind = m.get_type()
    if kind not in REPLY_TYPES:
        return None
    s = int(m.get_srcSystem())
    if kind == "COMMAND_ACK":
        return (kind, s, int(m.command), int(m.result))
    if kind == "MISSION_ACK":
        return (kind, s, int(m.type), 0)
    if kind in ("MISSION_REQUEST_INT", "MISSION_REQUEST", "MISSION_ITEM_INT", "MISSION_ITEM"):
        return (kind, s, int(m.seq), 0)
    if kind == "PARAM_VALUE":
        return (kind, s, int(m.param_index), 0)
    if kind == "MESSAGE_INTERVAL":
        return (kind, s, int(m.message_id), 0)
    return (kind, s, int(m.count), 0)  # MISSION_COUNT


@dataclass
class Datagram:
    sender: str  # "junk", "stranger" or "client"
    data: bytes
    frames: int
    expect: list[Reply] = field(default_factory=list)


@dataclass(frozen=True)
class V1:
    """A message to frame as MAVLink 1."""

    msg: Msg


@dataclass(frozen=True)
class Target:
    """One of our vehicles as the fuzzer sees it: sysid, in the air or not, home lat/lon."""

    sysid: int
    airborne: bool
    lat: float
    lon: float


Case = tuple[list[Msg], list[Reply]]


CaseMethod = Callable[[Any, Target], Case]


def _stateless(case: CaseMethod) -> CaseMethod:
    """Mark a case of one frame that needs no state on the vehicle (see ``Fuzzer.simple``)."""
    setattr(case, "stateless", True)  # noqa: B010 - an attribute a function cannot declare
    return case


class Fuzzer:
    """Deterministic for a seed: ``datagrams(n_frames)`` yields the same traffic every run."""

    def __init__(self, seed: int, targets: list[Target]) -> None:
        self.rng = random.Random(seed)
        self.targets = targets
        self.client = new_mav(*CLIENT)
        self.stranger = new_mav(*STRANGER)
        self.impostors = {t.sysid: new_mav(t.sysid, 1) for t in targets}
        self.ours = {t.sysid for t in targets}
        self.cases: list[Callable[[Target], Case]] = [
            self.bad_arm,
            self.disarm_in_air,
            self.bad_takeoff,
            self.bad_reposition,
            self.bad_set_mode,
            self.bad_pause,
            self.unknown_command,
            self.bad_message_interval,
            self.bad_request_message,
            self.bad_position_target,
            self.mission_count_too_big,
            self.mission_other_type,
            self.mission_out_of_order,
            self.mission_bad_item,
            self.mission_bad_float_item,
            self.mission_wrong_type_item,
            self.mission_item_without_count,
            self.mission_request_out_of_range,
            self.bad_param_set,
            self.unknown_param,
            self.mission_set_current_out_of_range,
            self.broadcast,
            self.mavlink1,
        ]
        # stateless one-frame cases (marked @_stateless): safe to send to every vehicle at
        # once, or as MAVLink 1
        self.simple = [case for case in self.cases if getattr(case, "stateless", False)]
        self.counts: dict[str, int] = {}

    # ------------------------------------------------------------------ helpers
    def _float(self, lo: float = -1e6, hi: float = 1e6) -> float:
        return self.rng.uniform(lo, hi)

    def _bad(self) -> float:
        return self.rng.choice(BAD_FLOATS)

    def _command(self, t: Target, command: int, p: list[float], as_int: bool = False) -> Msg:
        """COMMAND_LONG, or COMMAND_INT (params 5/6 in degE7; NaN there means 'absent')."""
        p = [*p, *([0.0] * (7 - len(p)))]
        if not as_int:
            return M.MAVLink_command_long_message(t.sysid, 1, command, 0, *p)
        x, y = (round(v * 1e7) if abs(v) < 214.0 else INT32_MAX for v in (p[4], p[5]))
        frame = self.rng.choice([int(M.MAV_FRAME_GLOBAL_INT), REL_INT])
        return M.MAVLink_command_int_message(t.sysid, 1, frame, command, 0, 0, *p[:4], x, y, p[6])

    def _ack(self, t: Target, command: int, result: int) -> Reply:
        return ("COMMAND_ACK", t.sysid, command, result)

    def _item(self, t: Target, seq: int, **kw: Any) -> Msg:
        """A good waypoint near home (relative altitude), fields overridable."""
        f: dict[str, Any] = dict(
            frame=REL_INT,
            command=16,
            param1=0.0,
            param2=0.0,
            param4=NAN,
            x=round((t.lat + self._float(-1e-3, 1e-3)) * 1e7),
            y=round((t.lon + self._float(-1e-3, 1e-3)) * 1e7),
            z=self._float(2.0, 50.0),
            mission_type=0,
        )
        f.update(kw)
        return M.MAVLink_mission_item_int_message(
            t.sysid,
            1,
            seq,
            f["frame"],
            f["command"],
            0,
            1,
            f["param1"],
            f["param2"],
            0.0,
            f["param4"],
            f["x"],
            f["y"],
            f["z"],
            f["mission_type"],
        )

    def _count(self, t: Target, n: int, mission_type: int = 0) -> Msg:
        return M.MAVLink_mission_count_message(t.sysid, 1, n, mission_type)

    def _request(self, t: Target, seq: int) -> Reply:
        return ("MISSION_REQUEST_INT", t.sysid, seq, 0)

    def _mission_ack(self, t: Target, result: int) -> Reply:
        return ("MISSION_ACK", t.sysid, result, 0)

    # ------------------------------------------------------------------ commands
    @_stateless
    def bad_arm(self, t: Target) -> Case:
        p1 = self.rng.choice([NAN, INF, -INF, 0.5, 2.0, -1.0, 1e30, 21196.0])
        msg = self._command(t, 400, [p1, self._float()], self.rng.random() < 0.5)
        return [msg], [self._ack(t, 400, DENIED)]

    def disarm_in_air(self, t: Target) -> Case:
        if not t.airborne:
            return self.bad_arm(t)
        p2 = self.rng.choice([NAN, INF, 0.0, 21195.0, self._float()])
        return [self._command(t, 400, [0.0, p2])], [self._ack(t, 400, TEMP_REJECTED)]

    @_stateless
    def bad_takeoff(self, t: Target) -> Case:
        """Altitude infinite, zero, negative or absurd (NaN alone means MIS_TAKEOFF_ALT)."""
        z = self.rng.choice(
            [INF, -INF, 1e30, -1e30, -self._float(1.0, 1e4), 2e4 + self._float(0, 1e6)]
        )
        as_int = self.rng.random() < 0.5
        if as_int:
            msg = self._command(t, 22, [NAN, 0, 0, NAN, NAN, NAN, z], as_int=True)
            msg.frame = REL_INT
        else:
            msg = self._command(t, 22, [NAN, 0, 0, NAN, NAN, NAN, z])
        return [msg], [self._ack(t, 22, DENIED)]

    @_stateless
    def bad_reposition(self, t: Target) -> Case:
        """Latitude / longitude out of range or infinite, or an infinite altitude."""
        kind = self.rng.randrange(3)
        lat, lon, alt = t.lat, t.lon, NAN
        if kind == 0:
            lat = self.rng.choice([1, -1]) * self._float(90.001, 214.0)
        elif kind == 1:
            lon = self.rng.choice([1, -1]) * self._float(180.001, 214.0)
        else:
            lat, lon, alt = NAN, NAN, self.rng.choice([INF, -INF])
        as_int = self.rng.random() < 0.5
        if not as_int and kind < 2 and self.rng.random() < 0.3:
            lat, lon = (INF, lon) if kind == 0 else (lat, -INF)
        msg = self._command(t, 192, [-1.0, 1.0, 0.0, NAN, lat, lon, alt], as_int=as_int)
        return [msg], [self._ack(t, 192, DENIED)]

    @_stateless
    def bad_set_mode(self, t: Target) -> Case:
        kind = self.rng.randrange(3)
        if kind == 0:  # not a finite mode
            p = [self._bad(), 4.0, 4.0]
            self.rng.shuffle(p)
        elif kind == 1:  # no custom-mode bit
            p = [float(self.rng.randrange(0, 256, 2)), 4.0, 3.0]
        elif kind == 2:  # manual, altitude, acro, stabilized: no RC here (position: sticks)
            p = [1.0, float(self.rng.choice([1, 2, 5, 7, 8, 99])), 0.0]
        else:  # AUTO with an unknown sub mode
            p = [1.0, 4.0, float(self.rng.choice([0, 1, 7, 9, 200]))]
        return [self._command(t, 176, p, self.rng.random() < 0.5)], [self._ack(t, 176, DENIED)]

    @_stateless
    def bad_pause(self, t: Target) -> Case:
        p1 = self.rng.choice([NAN, INF, 2.0, -1.0, 0.5, 1e9])
        return [self._command(t, 193, [p1])], [self._ack(t, 193, DENIED)]

    @_stateless
    def unknown_command(self, t: Target) -> Case:
        while (command := self.rng.randrange(65536)) in KNOWN_COMMANDS:
            pass
        p = [self.rng.choice([NAN, INF, self._float()]) for _ in range(7)]
        msg = self._command(t, command, p, self.rng.random() < 0.3)
        return [msg], [self._ack(t, command, UNSUPPORTED)]

    @_stateless
    def bad_message_interval(self, t: Target) -> Case:
        if self.rng.random() < 0.5:  # SET: NaN / unknown stream / NaN interval
            p = self.rng.choice(
                [[NAN, 1e5], [float(self.rng.randrange(400, 65536)), 1e5], [30.0, NAN], [-5.0, 0]]
            )
            return [self._command(t, 511, p)], [self._ack(t, 511, DENIED)]
        p1 = self.rng.choice([NAN, INF, -1.0, 65536.0, 1e12])
        return [self._command(t, 510, [p1])], [self._ack(t, 510, DENIED)]

    @_stateless
    def bad_request_message(self, t: Target) -> Case:
        p1 = self.rng.choice([NAN, INF, -1.0, 1e12, 435.0, 397.0, 395.0, 65535.0])
        return [self._command(t, 512, [p1])], [self._ack(t, 512, UNSUPPORTED)]

    def bad_position_target(self, t: Target) -> Case:
        """Offboard setpoints with NaN / infinite / absurd values: dropped, no answer."""
        v = [self.rng.choice([NAN, INF, -INF, 1e30, -1e12]) for _ in range(6)]
        if self.rng.random() < 0.8:
            msg = M.MAVLink_set_position_target_local_ned_message(
                0, t.sysid, 1, int(M.MAV_FRAME_LOCAL_NED), 0, *v, 0, 0, 0, NAN, 0
            )
        else:  # the global variant is not handled at all
            lat = round(self._float(-214, 214) * 1e7)
            msg = M.MAVLink_set_position_target_global_int_message(
                0, t.sysid, 1, 6, 0, lat, lat, v[0], *v[3:], 0, 0, 0, NAN, 0
            )
        return [msg], []

    # ------------------------------------------------------------------ missions
    def mission_count_too_big(self, t: Target) -> Case:
        n = self.rng.choice([65535, 1001, self.rng.randrange(1001, 65536)])
        return [self._count(t, n)], [self._mission_ack(t, M.MAV_MISSION_NO_SPACE)]

    def mission_other_type(self, t: Target) -> Case:
        mission_type = self.rng.choice([3, 7, 254, 255])  # no such plan (255: only clear-all)
        msg = self.rng.choice(
            [
                self._count(t, self.rng.randrange(1, 10), mission_type),
                M.MAVLink_mission_request_list_message(t.sysid, 1, mission_type),
                M.MAVLink_mission_request_int_message(t.sysid, 1, 0, mission_type),
            ]
        )
        if mission_type != 255 and self.rng.random() < 0.3:
            msg = M.MAVLink_mission_clear_all_message(t.sysid, 1, mission_type)
        return [msg], [self._mission_ack(t, M.MAV_MISSION_UNSUPPORTED)]

    def mission_out_of_order(self, t: Target) -> Case:
        """COUNT n, items 0..k-1 (with duplicates), then one that skips ahead."""
        n = self.rng.randrange(2, 8)
        k = self.rng.randrange(0, n - 1)
        msgs = [self._count(t, n)]
        expect = [self._request(t, 0)]
        for seq in range(k):
            msgs.append(self._item(t, seq))
            expect.append(self._request(t, seq + 1))
            if self.rng.random() < 0.3:  # a duplicate: ignored
                msgs.append(self._item(t, self.rng.randrange(seq + 1)))
        msgs.append(self._item(t, self.rng.randrange(k + 1, max(k + 2, 65536))))
        expect.append(self._mission_ack(t, M.MAV_MISSION_INVALID_SEQUENCE))
        return msgs, expect

    def _bad_field(self, t: Target) -> tuple[dict[str, Any], int]:
        kind = self.rng.randrange(7)
        sign = self.rng.choice([1, -1])
        if kind == 0:
            return {
                "x": sign * self.rng.randrange(900_000_001, 2**31 - 1)
            }, M.MAV_MISSION_INVALID_PARAM5_X
        if kind == 1:
            return {
                "y": sign * self.rng.randrange(1_800_000_001, 2**31 - 1)
            }, M.MAV_MISSION_INVALID_PARAM6_Y
        if kind == 2:
            return {"z": self.rng.choice([NAN, INF, -INF, 1e30])}, M.MAV_MISSION_INVALID_PARAM7
        if kind == 3:
            return {"param1": self.rng.choice([NAN, INF, -1.0, 1e7])}, M.MAV_MISSION_INVALID_PARAM1
        if kind == 4:
            return {"param2": self.rng.choice([1001.0, 1e30, INF])}, M.MAV_MISSION_INVALID_PARAM2
        if kind == 5:
            while (command := self.rng.randrange(65536)) in (16, 19, 20, 21, 22, 178):
                pass
            return {"command": command}, M.MAV_MISSION_UNSUPPORTED
        frame = self.rng.choice([1, 7, 8, 9, 12, 200])  # local, body, ...: not global
        return {"frame": frame}, M.MAV_MISSION_UNSUPPORTED_FRAME

    def mission_bad_item(self, t: Target) -> Case:
        """A complete upload with one invalid item: refused whole, before the autopilot."""
        n = self.rng.randrange(1, 6)
        bad_seq = self.rng.randrange(n)
        fields, result = self._bad_field(t)
        msgs = [self._count(t, n)]
        expect = [self._request(t, 0)]
        for seq in range(n):
            msgs.append(self._item(t, seq, **(fields if seq == bad_seq else {})))
            expect.append(
                self._request(t, seq + 1) if seq + 1 < n else self._mission_ack(t, result)
            )
        return msgs, expect

    def mission_bad_float_item(self, t: Target) -> Case:
        """MISSION_ITEM (float lat/lon) with a non-finite or out-of-range waypoint position."""
        lat, lon = t.lat, t.lon
        if self.rng.random() < 0.5:
            lat, result = self.rng.choice([NAN, INF, 91.0, -1e9]), M.MAV_MISSION_INVALID_PARAM5_X
        else:
            lon, result = self.rng.choice([NAN, -INF, 181.0, 1e9]), M.MAV_MISSION_INVALID_PARAM6_Y
        item = M.MAVLink_mission_item_message(
            t.sysid,
            1,
            0,
            int(M.MAV_FRAME_GLOBAL_RELATIVE_ALT),
            16,
            0,
            1,
            0,
            0,
            0,
            NAN,
            lat,
            lon,
            10.0,
        )
        msgs = [self._count(t, self.rng.randrange(1, 5)), item]
        return msgs, [self._request(t, 0), self._mission_ack(t, result)]

    def mission_wrong_type_item(self, t: Target) -> Case:
        msgs = [self._count(t, 3), self._item(t, 0, mission_type=self.rng.choice([1, 2, 9]))]
        return msgs, [self._request(t, 0), self._mission_ack(t, M.MAV_MISSION_INVALID)]

    def mission_item_without_count(self, t: Target) -> Case:
        """No transfer going on: ignored (PX4 too), a late duplicate must not fail an upload."""
        return [self._item(t, self.rng.randrange(65536))], []

    def mission_request_out_of_range(self, t: Target) -> Case:
        """Download requests with no download going on (nothing listed): INVALID_SEQUENCE."""
        msg = M.MAVLink_mission_request_int_message(t.sysid, 1, self.rng.randrange(65536), 0)
        return [msg], [self._mission_ack(t, M.MAV_MISSION_INVALID_SEQUENCE)]

    def mission_set_current_out_of_range(self, t: Target) -> Case:
        """Jump to an item that does not exist: refused by the gateway (STATUSTEXT and
        MISSION_CURRENT, neither of them counted), never a mission start."""
        return [
            M.MAVLink_mission_set_current_message(t.sysid, 1, self.rng.randrange(50, 65536))
        ], []

    # ------------------------------------------------------------------ addressing, framing
    def broadcast(self, t: Target) -> Case:
        """A simple case for target system 0: every vehicle of the link answers."""
        msgs, replies = self.rng.choice(self.simple)(t)
        for m in msgs:
            m.target_system = 0
        return msgs, [(r[0], u.sysid, r[2], r[3]) for u in self.targets for r in replies]

    def mavlink1(self, t: Target) -> Case:
        """A simple case framed as MAVLink 1 (no signing possible, still parsed)."""
        msgs, replies = self.rng.choice(self.simple)(t)
        return [V1(m) for m in msgs], replies

    # ------------------------------------------------------------------ parameters
    @_stateless
    def bad_param_set(self, t: Target) -> Case:
        """A known parameter set to NaN / inf / out of range: PARAM_VALUE with the old value."""
        index = self.rng.randrange(len(SPECS))
        spec = SPECS[index]
        value = self.rng.choice([NAN, INF, -INF, spec.max_value * 2 + 1e6, spec.min_value - 1e6])
        msg = M.MAVLink_param_set_message(t.sysid, 1, spec.name.encode(), value, spec.param_type)
        return [msg], [("PARAM_VALUE", t.sysid, index, 0)]

    def unknown_param(self, t: Target) -> Case:
        name = "".join(self.rng.choice("ABCXYZ_0123") for _ in range(self.rng.randrange(1, 17)))
        if self.rng.random() < 0.5:
            return [M.MAVLink_param_set_message(t.sysid, 1, name.encode(), NAN, 9)], []
        index = self.rng.choice([len(SPECS), 1000, 32767])
        return [M.MAVLink_param_request_read_message(t.sysid, 1, b"", index)], []

    # ------------------------------------------------------------------ junk and strangers
    def junk(self) -> bytes:
        """Random bytes, a random MAVLink-looking frame, or a broken copy of a real one."""
        kind = self.rng.randrange(3)
        if kind == 0:
            return self.rng.randbytes(self.rng.randrange(1, 300))
        if kind == 1:  # magic + plausible header + random payload and CRC
            n = self.rng.randrange(0, 256)
            head = bytes([0xFD, n, self.rng.choice([0, 0, 1, 2]), 0])
            return head + self.rng.randbytes(6 + n + 2)
        frame = bytearray(self._valid_frame())  # bad CRC: one byte changed after the length
        i = self.rng.randrange(2, len(frame))
        frame[i] ^= self.rng.randrange(1, 256)
        return bytes(frame)

    def truncated(self) -> bytes:
        """A real frame cut short (only ever last in a datagram: never completed by the next)."""
        frame = self._valid_frame()
        return frame[: self.rng.randrange(1, len(frame))]

    def _valid_frame(self) -> bytes:
        """A frame that would act if it arrived whole: ARM the target, or take off."""
        t = self.rng.choice(self.targets)
        if self.rng.random() < 0.5:
            msg = M.MAVLink_command_long_message(t.sysid, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        else:
            msg = M.MAVLink_command_long_message(t.sysid, 1, 22, 0, 0, 0, 0, NAN, 0, 0, 10.0)
        return bytes(pack(self.client, msg))

    def stranger_frame(self) -> bytes:
        """A well-formed, valid command for someone else (or from one of our own sysids)."""
        t = self.rng.choice(self.targets)
        kind = self.rng.randrange(3)
        if kind == 0:  # another system
            system = self.rng.choice([s for s in range(1, 256) if s not in self.ours])
            component = 1
        elif kind == 1:  # another component of our vehicle
            system, component = t.sysid, self.rng.randrange(2, 256)
        else:  # claims to be one of our vehicles (a forwarding client echoing us)
            system, component = t.sysid, 1
        msg = self.rng.choice(
            [
                M.MAVLink_command_long_message(system, component, 400, 0, 1, 0, 0, 0, 0, 0, 0),
                M.MAVLink_command_long_message(system, component, 22, 0, 0, 0, 0, NAN, 0, 0, 10),
                M.MAVLink_command_long_message(system, component, 176, 0, 1, 4, 4, 0, 0, 0, 0),
                M.MAVLink_set_mode_message(system, 1, 4 << 16 | 5 << 24),
                M.MAVLink_mission_count_message(system, component, 2, 0),
                M.MAVLink_mission_clear_all_message(system, component, 0),
                M.MAVLink_param_set_message(system, component, b"NAV_DLL_ACT", 0.0, 6),
                M.MAVLink_command_int_message(
                    system,
                    component,
                    6,
                    192,
                    0,
                    0,
                    -1,
                    1,
                    0,
                    NAN,
                    round(t.lat * 1e7),
                    round(t.lon * 1e7),
                    30,
                ),
            ]
        )
        if kind == 2:
            msg.target_system, msg.target_component = t.sysid, 1
            return bytes(pack(self.impostors[t.sysid], msg))
        if msg.get_type() == "SET_MODE" and kind == 1:  # no component field: another system
            msg.target_system = self.rng.choice([s for s in range(1, 256) if s not in self.ours])
        return bytes(pack(self.stranger, msg))

    # ------------------------------------------------------------------ traffic
    def datagrams(self, n_frames: int, per_datagram: int = 8) -> list[Datagram]:
        """About ``n_frames`` frames: 25 % junk, 15 % strangers, 60 % the client's."""
        out: list[Datagram] = []
        frames = 0
        while frames < n_frames:
            r = self.rng.random()
            if r < 0.25:
                parts = [self.junk() for _ in range(per_datagram // 2)]
                if self.rng.random() < 0.5:
                    parts.append(self.truncated())
                out.append(Datagram("junk", b"".join(parts), len(parts)))
            elif r < 0.40:
                parts = [self.stranger_frame() for _ in range(per_datagram)]
                out.append(Datagram("stranger", b"".join(parts), len(parts)))
            else:
                data = b""
                expect: list[Reply] = []
                count = 0
                while count < per_datagram:
                    case = self.rng.choice(self.cases)
                    msgs, replies = case(self.rng.choice(self.targets))
                    self.counts[case.__name__] = self.counts.get(case.__name__, 0) + len(msgs)
                    data += b"".join(self._pack(m) for m in msgs)
                    expect += replies
                    count += len(msgs)
                out.append(Datagram("client", data, count, expect))
            frames += out[-1].frames
        return out

    def _pack(self, m: Msg) -> bytes:
        if isinstance(m, V1):
            buf: bytes = m.msg.pack(self.client, force_mavlink1=True)
            self.client.seq = (self.client.seq + 1) % 256
            return buf
        return bytes(pack(self.client, m))

    def sentinel(self, t: Target, token: int) -> tuple[bytes, list[Reply]]:
        """GET_MESSAGE_INTERVAL of a non-stream id: its MESSAGE_INTERVAL closes a batch."""
        msg = M.MAVLink_command_long_message(t.sysid, 1, GET_INTERVAL, 0, token, 0, 0, 0, 0, 0, 0)
        return bytes(pack(self.client, msg)), [
            ("COMMAND_ACK", t.sysid, GET_INTERVAL, ACCEPTED),
            ("MESSAGE_INTERVAL", t.sysid, token, 0),
        ]
