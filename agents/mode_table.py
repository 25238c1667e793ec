"""The flight modes' transition table: ``TRANSITIONS[action][from_mode] → to_mode`` lists every
allowed transition, ``REFUSALS`` says why an action is refused in a mode the table does not list
(docs/agents.md, "Flight modes"). :mod:`agents.modes` checks the guards that depend on more than
the mode and guides each mode."""

from __future__ import annotations

import enum
from dataclasses import dataclass

from swarmbus.messages import FlightMode, RejectCode

M = FlightMode
AIRBORNE = frozenset(
    {M.TAKEOFF, M.HOLD, M.MISSION, M.LAND, M.RTL, M.OFFBOARD, M.ORBIT, M.POSITION, M.FOLLOW}
)


class Action(enum.StrEnum):
    ARM = "arm"
    DISARM = "disarm"
    TAKEOFF = "takeoff"
    LAND = "land"
    RTL = "rtl"
    HOLD = "hold"
    GOTO = "goto"
    MISSION = "mission"
    OFFBOARD = "offboard"
    ORBIT = "orbit"
    POSITION = "position"
    FOLLOW = "follow"


def _all_airborne(to: FlightMode) -> dict[FlightMode, FlightMode]:
    return dict.fromkeys(AIRBORNE, to)


TRANSITIONS: dict[Action, dict[FlightMode, FlightMode]] = {
    Action.ARM: {M.DISARMED: M.ARMED},
    Action.DISARM: {M.ARMED: M.DISARMED, **_all_airborne(M.DISARMED)},  # airborne: force
    Action.TAKEOFF: {M.ARMED: M.TAKEOFF},
    Action.LAND: _all_airborne(M.LAND),
    Action.RTL: _all_airborne(M.RTL),
    Action.HOLD: _all_airborne(M.HOLD),
    Action.GOTO: _all_airborne(M.HOLD),
    Action.MISSION: {M.ARMED: M.MISSION, **_all_airborne(M.MISSION)},
    Action.OFFBOARD: {M.ARMED: M.OFFBOARD, **_all_airborne(M.OFFBOARD)},
    Action.ORBIT: _all_airborne(M.ORBIT),
    Action.POSITION: _all_airborne(M.POSITION),
    Action.FOLLOW: _all_airborne(M.FOLLOW),
}

_NOT_FLYING = "disarmed: not flying"
_ON_GROUND = "on the ground: take off first"
REFUSALS: dict[Action, dict[FlightMode, str]] = {
    Action.ARM: {M.ARMED: "already armed", **dict.fromkeys(AIRBORNE, "already armed and flying")},
    Action.DISARM: {M.DISARMED: "already disarmed"},
    Action.TAKEOFF: {
        M.DISARMED: "disarmed: arm before taking off",
        **dict.fromkeys(AIRBORNE, "already flying: use goto, hold or a mission"),
    },
    Action.LAND: {M.DISARMED: _NOT_FLYING, M.ARMED: "already on the ground"},
    Action.RTL: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
    Action.HOLD: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
    Action.GOTO: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
    Action.MISSION: {M.DISARMED: "disarmed: arm before starting a mission"},
    Action.OFFBOARD: {M.DISARMED: "disarmed: arm before switching to offboard"},
    Action.ORBIT: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
    Action.POSITION: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
    Action.FOLLOW: {M.DISARMED: _NOT_FLYING, M.ARMED: _ON_GROUND},
}


@dataclass(frozen=True, slots=True)
class Refusal:
    code: RejectCode
    reason: str


def denied(reason: str) -> Refusal:
    return Refusal(RejectCode.DENIED, reason)


def invalid(reason: str) -> Refusal:
    return Refusal(RejectCode.INVALID, reason)


class RtlPhase(enum.Enum):
    CLIMB = "climb"
    RETURN = "return"
    DESCEND = "descend"
