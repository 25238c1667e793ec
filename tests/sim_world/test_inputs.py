"""What arrives for the lockstep from the bus (docs/physics.md, Lockstep; Restarts; Stepped
clock), on a real Zenoh network: a second session plays the autopilot and the launcher."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from typing import TypeVar

import pytest
import zenoh

from sim_world.holds import Holds
from sim_world.inputs import LockstepInputs
from sim_world.lockstep import Lockstep
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    ActuatorBatch,
    ActuatorCommand,
    RestartNotice,
    StepReply,
    StepRequest,
)
from swarmbus.reqrep import Refused, request
from swarmbus.session import announce, open_session
from tests.support.procs import Network, wait_until

KEYS = Keys("inputs")
TIMEOUT_S = 5.0  # participant timeout: the wait for the launcher's word
GRACE_S = 30.0
REFUSAL = "world 'inputs' runs in lockstep mode, not stepped"
T = TypeVar("T")


@pytest.fixture
def wired(
    network: tuple[Network, zenoh.Session],
) -> Iterator[tuple[LockstepInputs, zenoh.Session]]:
    """Inputs on the network's session, and a peer session that speaks to them."""
    net, session = network
    barrier = Lockstep(["a", "b"], TIMEOUT_S, time.monotonic)
    holds = Holds(GRACE_S, TIMEOUT_S, time.monotonic, 0.1)
    inputs = LockstepInputs(session, KEYS, barrier, holds, lambda: 0, REFUSAL)
    with open_session(net.client) as peer:
        try:
            yield inputs, peer
        finally:
            inputs.close()


def batch(tick: int, *vehicles: str) -> bytes:
    rotors = [0.5] * 4
    commands = [ActuatorCommand(vehicle_id=v, tick=tick, rotor_commands=rotors) for v in vehicles]
    return encode(ActuatorBatch(tick=tick, commands=commands))


def locked(inputs: LockstepInputs, read: Callable[[], T]) -> T:
    """``read()`` under the inputs' lock (their callbacks change the barrier on Zenoh threads)."""
    with inputs.cond:
        return read()


def begin_tick_0(inputs: LockstepInputs) -> None:
    with inputs.cond:
        inputs.barrier.start()
        inputs.barrier.begin(0)


def test_tokens_and_batches_complete_a_tick(wired: tuple[LockstepInputs, zenoh.Session]) -> None:
    inputs, peer = wired
    tokens = [announce(peer, KEYS, "autopilot-a"), announce(peer, KEYS, "autopilot-b")]
    wait_until(
        lambda: locked(inputs, lambda: not inputs.barrier.missing_tokens()), 10.0, "two tokens"
    )
    begin_tick_0(inputs)
    # a's one-vehicle key naming b too: a's entry counts, b's is dropped; then a process that
    # serves several vehicles (a node name of no vehicle) answers for b.
    peer.put(KEYS.autopilot_actuators("autopilot-a"), batch(0, "a", "b"))
    wait_until(lambda: inputs.intake.foreign_dropped == 1, 10.0, "b's entry dropped on a's key")
    assert not locked(inputs, inputs.barrier.complete)
    peer.put(KEYS.autopilot_actuators("autopilots-0"), batch(0, "b"))
    wait_until(lambda: locked(inputs, inputs.barrier.complete), 10.0, "tick 0 complete")
    assert sorted(locked(inputs, inputs.barrier.commands)) == ["a", "b"]
    for token in tokens:
        token.undeclare()


def test_a_restarting_autopilot_is_held_for_its_backoff_and_the_grace(
    wired: tuple[LockstepInputs, zenoh.Session],
) -> None:
    inputs, peer = wired
    token = announce(peer, KEYS, "autopilot-a")
    wait_until(lambda: locked(inputs, lambda: inputs.barrier.present == {"a"}), 10.0, "a's token")
    begin_tick_0(inputs)
    token.undeclare()
    wait_until(lambda: locked(inputs, lambda: inputs.barrier.held == {"a"}), 10.0, "a held")
    assert locked(inputs, inputs.barrier.remaining_s) <= TIMEOUT_S
    notice = RestartNotice(
        node="autopilot-a", role="autopilot", restarting=True, returncode=-9, delay_s=2.0,
        vehicles=["a"],
    )  # fmt: skip
    peer.put(KEYS.node_restart("autopilot-a"), encode(notice))
    wait_until(
        lambda: locked(inputs, inputs.barrier.remaining_s) > TIMEOUT_S + 1.0,
        10.0,
        "the hold extended by the notice",
    )
    assert locked(inputs, inputs.barrier.remaining_s) <= 2.0 + GRACE_S


def test_the_step_queryable_refuses_outside_stepped_mode(
    wired: tuple[LockstepInputs, zenoh.Session],
) -> None:
    _, peer = wired
    with pytest.raises(Refused) as refused:
        request(peer, KEYS.clock_step(), StepRequest(client="clock-x", ticks=1), StepReply, 10.0)
    assert (refused.value.field, refused.value.reason) == ("mode", REFUSAL)
