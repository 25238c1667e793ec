"""Node names and partial-decode views live in swarmbus, one copy each: they must read what the
full messages encode and name processes the way the launcher, lockstep and clients expect."""

from __future__ import annotations

import msgspec
import pytest

from swarmbus.codec import decode, encode
from swarmbus.keys import (
    KeyNameError,
    Keys,
    autopilot_node,
    process_node,
    serves_several,
    vehicle_of_autopilot,
)
from swarmbus.messages import ActuatorBatch, ActuatorCommand, SimTick, VehicleState
from swarmbus.views import (
    BatchView,
    StateHead,
    StateKey,
    TickView,
    state_head_decoder,
    state_key_decoder,
)
from tests.support.messages_samples import STATE


def test_node_names() -> None:
    assert autopilot_node("uav1") == "autopilot-uav1"
    assert vehicle_of_autopilot("autopilot-uav-2") == "uav-2"
    assert vehicle_of_autopilot("physics") is None
    assert process_node("physics") == "physics"
    assert process_node("autopilot", ["uav1"]) == "autopilot-uav1"
    assert process_node("autopilot", ["uav1", "uav2", "uav3"]) == "autopilot-uav1-plus2"
    assert serves_several(process_node("autopilot", ["uav1", "uav2"]))
    assert serves_several(process_node("autopilot", [f"uav{k}" for k in range(1, 33)]))
    for single in ("autopilot-uav1", "autopilot-uav-2", "autopilot-plus", "autopilot-a-plus0"):
        assert not serves_several(single), single
    with pytest.raises(KeyNameError):
        autopilot_node("a/b")


def test_names_are_read_back_from_keys_of_this_world_and_plane_only() -> None:
    keys = Keys("w1")
    assert keys.vehicle_id_of("plumeswarm/w1/vehicle/uav1/state") == "uav1"
    assert keys.vehicle_id_of("plumeswarm/w1/vehicle/uav1/a/b") == "uav1"
    assert keys.node_name_of("plumeswarm/w1/node/physics/health") == "physics"
    assert keys.autopilot_node_of("plumeswarm/w1/autopilot/autopilot-0/actuators") == "autopilot-0"
    refused = [
        (keys.vehicle_id_of, "plumeswarm/w2/vehicle/uav1/state", "a vehicle"),  # other world
        (keys.vehicle_id_of, "plumeswarm/w1/node/uav1/state", "a vehicle"),  # other plane
        (keys.vehicle_id_of, "plumeswarm/w1/vehicle/uav1", "a vehicle"),  # no leaf
        (keys.node_name_of, "plumeswarm/w1/vehicle/physics/health", "a node"),
        (keys.autopilot_node_of, "plumeswarm/w1/autopilot/a/actuators/x", "an autopilot"),
        (keys.autopilot_node_of, "plumeswarm/w1/autopilot/a", "an autopilot"),
    ]
    for parse, key, what in refused:
        with pytest.raises(KeyNameError, match=f"is not {what} key of world 'w1'"):
            parse(key)


def test_views_read_what_the_full_messages_encode() -> None:
    other = msgspec.structs.replace(STATE, vehicle_id="uav2", position_enu_m=(1.0, 2.0, 3.0))
    tick = SimTick(tick=7, sim_time_s=0.5, control_dt_s=1 / 120, states=[STATE, other])
    view = decode(encode(tick), TickView)
    assert (view.tick, view.sim_time_s, view.plume_queried, view.plume_values) == (
        7,
        0.5,
        False,
        None,
    )
    heads = [state_head_decoder.decode(raw) for raw in view.states]
    assert heads == [
        StateHead(STATE.vehicle_id, STATE.position_enu_m),
        StateHead("uav2", (1.0, 2.0, 3.0)),
    ]
    assert [decode(bytes(raw), VehicleState) for raw in view.states] == [STATE, other]
    assert [state_key_decoder.decode(raw) for raw in view.states] == [
        StateKey(STATE.vehicle_id, STATE.tick),
        StateKey("uav2", STATE.tick),
    ]

    cmd = ActuatorCommand(vehicle_id="uav1", tick=7, rotor_commands=[0.5] * 4)
    batch = decode(encode(ActuatorBatch(tick=7, commands=[cmd])), BatchView)
    assert batch.tick == 7 and [decode(bytes(r), ActuatorCommand) for r in batch.commands] == [cmd]
