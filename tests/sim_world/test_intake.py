"""The actuator intake's rules (docs/physics.md, Lockstep 3 and 5) by direct calls: which
entries of a batch count, which are dropped and counted."""

from __future__ import annotations

from collections.abc import Sequence

from sim_world.intake import ActuatorIntake
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import ActuatorBatch, ActuatorCommand

KEYS = Keys("intake")
VEHICLES = ("uav1", "uav2", "uav3")


def intake() -> ActuatorIntake:
    return ActuatorIntake(VEHICLES, KEYS.autopilot_node_of)


def batch(tick: int, *entries: tuple[str, int, list[float]]) -> bytes:
    commands = [ActuatorCommand(vehicle_id=v, tick=t, rotor_commands=r) for v, t, r in entries]
    return encode(ActuatorBatch(tick=tick, commands=commands))


Taken = tuple[int, list[tuple[str, Sequence[float]]]]


def take(token: str, data: bytes) -> tuple[Taken, int]:
    """A new intake's entries of ``data`` on the actuator key of ``token``, and the foreign
    entries it counted."""
    taker = intake()
    return taker.entries(KEYS.autopilot_actuators(token), data), taker.foreign_dropped


def test_a_process_serving_several_vehicles_commands_each_of_them() -> None:
    data = batch(7, ("uav2", 7, [0.5] * 4), ("uav1", 7, [0.25] * 4))
    assert take("autopilot-0", data) == ((7, [("uav2", [0.5] * 4), ("uav1", [0.25] * 4)]), 0)


def test_a_one_vehicle_key_commands_only_its_own_vehicle_and_counts_the_others() -> None:
    taker = intake()
    key = KEYS.autopilot_actuators("autopilot-uav1")
    data = batch(3, ("uav1", 3, [0.1] * 4), ("uav2", 3, [0.9] * 4), ("uav3", 3, [0.9] * 4))
    assert taker.entries(key, data) == (3, [("uav1", [0.1] * 4)])
    assert taker.foreign_dropped == 2
    taker.entries(key, batch(4, ("uav2", 4, [0.9] * 4)))
    assert taker.foreign_dropped == 3


def test_a_token_of_an_unknown_vehicle_is_no_one_vehicle_key() -> None:
    data = batch(1, ("uav3", 1, [0.3] * 4))
    assert take("autopilot-ghost", data) == ((1, [("uav3", [0.3] * 4)]), 0)


def test_entries_of_another_tick_or_an_unknown_vehicle_are_dropped_uncounted() -> None:
    data = batch(5, ("uav1", 4, [0.2] * 4), ("ghost", 5, [0.2] * 4), ("uav3", 5, [0.7] * 4))
    assert take("autopilot-0", data) == ((5, [("uav3", [0.7] * 4)]), 0)


def test_a_bad_entry_sinks_only_itself() -> None:
    # 1.5 is outside a rotor command's 0..1: that entry fails to decode, the batch does not.
    data = batch(2, ("uav1", 2, [0.5] * 4), ("uav2", 2, [1.5] * 4), ("uav3", 2, [0.0] * 4))
    assert take("autopilot-0", data) == ((2, [("uav1", [0.5] * 4), ("uav3", [0.0] * 4)]), 0)


def test_bytes_that_are_no_batch_give_nothing() -> None:
    assert take("autopilot-0", b"\x93not a batch") == ((0, []), 0)
