"""Partial-decode views of bus messages: a process that needs a few fields of a large message
(a ``SimTick`` of every vehicle's state) decodes them alone and leaves the rest raw.

Each view carries the tag of the message it reads, so it decodes exactly what that message
encodes; fields it does not declare are skipped by msgspec.
"""

from __future__ import annotations

from typing import Annotated

import msgspec

from swarmbus.messages import (
    MAX_BATCH_COMMANDS,
    ActuatorBatch,
    PlumeSample,
    SimTick,
    SimTime,
    Tick,
    VehicleState,
)

TICK_TAG = str(SimTick.__struct_config__.tag)
STATE_TAG = str(VehicleState.__struct_config__.tag)
BATCH_TAG = str(ActuatorBatch.__struct_config__.tag)


class TickView(msgspec.Struct, frozen=True, tag_field="schema", tag=TICK_TAG):
    """A ``SimTick`` whose states stay undecoded (a reader decodes only the states it needs)."""

    tick: Tick
    sim_time_s: SimTime
    states: list[msgspec.Raw]
    plume_queried: bool = False
    plume_values: PlumeSample | None = None


class StateHead(msgspec.Struct, frozen=True, tag_field="schema", tag=STATE_TAG):
    """Who and where of a ``VehicleState`` (an autopilot's sensor query, the gateway's ids)."""

    vehicle_id: str
    position_enu_m: tuple[float, float, float]


state_head_decoder = msgspec.msgpack.Decoder(StateHead)


class StateKey(msgspec.Struct, frozen=True, tag_field="schema", tag=STATE_TAG):
    """Which vehicle and tick a ``VehicleState`` is of (ordering raw state payloads)."""

    vehicle_id: str
    tick: Tick


state_key_decoder = msgspec.msgpack.Decoder(StateKey)


class BatchView(msgspec.Struct, frozen=True, tag_field="schema", tag=BATCH_TAG):
    """An ``ActuatorBatch`` with undecoded entries: one bad entry does not sink the others."""

    tick: Tick
    commands: Annotated[list[msgspec.Raw], msgspec.Meta(max_length=MAX_BATCH_COMMANDS)]
