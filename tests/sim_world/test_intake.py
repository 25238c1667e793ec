"""The actuator intake's rules (docs/physics.md, Lockstep 3 and 5) by direct calls: which
entries of a batch count, which are dropped and counted."""

from __future__ import annotations

import pytest

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


# (the token the batch's key names, the batch, the entries taken, the foreign entries counted)
CASES: dict[str, tuple[str, bytes, tuple[int, list[tuple[str, list[float]]]], int]] = {
    "a process serving several vehicles commands each of them": (
        "autopilot-0",
        batch(7, ("uav2", 7, [0.5] * 4), ("uav1", 7, [0.25] * 4)),
        (7, [("uav2", [0.5] * 4), ("uav1", [0.25] * 4)]),
        0,
    ),
    "a one-vehicle key commands only its own vehicle and counts the others": (
        "autopilot-uav1",
        batch(3, ("uav1", 3, [0.1] * 4), ("uav2", 3, [0.9] * 4), ("uav3", 3, [0.9] * 4)),
        (3, [("uav1", [0.1] * 4)]),
        2,
    ),
    "a token of an unknown vehicle is no one-vehicle key": (
        "autopilot-ghost",
        batch(1, ("uav3", 1, [0.3] * 4)),
        (1, [("uav3", [0.3] * 4)]),
        0,
    ),
    "entries of another tick or an unknown vehicle are dropped uncounted": (
        "autopilot-0",
        batch(5, ("uav1", 4, [0.2] * 4), ("ghost", 5, [0.2] * 4), ("uav3", 5, [0.7] * 4)),
        (5, [("uav3", [0.7] * 4)]),
        0,
    ),
    # 1.5 is outside a rotor command's 0..1: that entry fails to decode, the batch does not.
    "a bad entry sinks only itself": (
        "autopilot-0",
        batch(2, ("uav1", 2, [0.5] * 4), ("uav2", 2, [1.5] * 4), ("uav3", 2, [0.0] * 4)),
        (2, [("uav1", [0.5] * 4), ("uav3", [0.0] * 4)]),
        0,
    ),
}


@pytest.mark.parametrize(("token", "data", "taken", "foreign"), CASES.values(), ids=CASES.keys())
def test_the_entries_a_batch_commands(
    token: str, data: bytes, taken: tuple[int, list[tuple[str, list[float]]]], foreign: int
) -> None:
    taker = intake()
    assert taker.entries(KEYS.autopilot_actuators(token), data) == taken
    assert taker.foreign_dropped == foreign


def test_the_foreign_count_adds_up_over_batches() -> None:
    taker = intake()
    key = KEYS.autopilot_actuators("autopilot-uav1")
    taker.entries(
        key, batch(3, ("uav1", 3, [0.1] * 4), ("uav2", 3, [0.9] * 4), ("uav3", 3, [0.9] * 4))
    )
    assert taker.foreign_dropped == 2
    taker.entries(key, batch(4, ("uav2", 4, [0.9] * 4)))
    assert taker.foreign_dropped == 3


def test_bytes_that_are_no_batch_give_nothing() -> None:
    key = KEYS.autopilot_actuators("autopilot-0")
    assert intake().entries(key, b"\x93not a batch") == (0, [])
