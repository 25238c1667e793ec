"""The stepped clock: the grant logic alone, then a real physics and autopilot stepped by a
``Swarm`` client (a command answered between two steps lands on the next tick)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from functools import partial
from pathlib import Path

import msgspec
import pytest

from agents import ClockError, Swarm, WaitTimeout
from deploy.scaling import write_scenario
from sim_world.stepping import SteppedClock, StepRefused
from swarmbus.messages import FlightMode, VehicleState, VehicleStatus
from swarmbus.scenario import Scenario, load_scenario
from tests.support.procs import Network, NodeProcs, wait_until, zenoh_network
from tests.support.upstack import plumeswarm_up

# ---------------------------------------------------------------------------- the logic


def test_a_grant_runs_to_its_tick_and_is_answered_there() -> None:
    clock: SteppedClock[str] = SteppedClock()
    assert not clock.may_advance(0)  # nothing granted: paused at the first tick
    assert clock.request("a", 3, paused_tick=0, answer_to="q1") == 3
    assert [clock.may_advance(t) for t in range(5)] == [True, True, True, False, False]
    assert clock.reached(2) is None
    assert clock.reached(3) == "q1" and clock.reached(3) is None  # answered once
    assert clock.request("a", 2, paused_tick=3, answer_to="q2") == 5


def test_one_holder_one_grant_at_a_time_and_free_when_the_holder_leaves() -> None:
    clock: SteppedClock[str] = SteppedClock()
    clock.request("a", 10, 0, "q1")
    with pytest.raises(StepRefused, match="held by a") as held:
        clock.request("b", 1, 0, "q2")
    assert held.value.field == "client"
    with pytest.raises(StepRefused, match="still running") as running:
        clock.request("a", 1, 0, "q3")
    assert running.value.field == "ticks"
    assert not clock.released("b") and clock.released("a")
    assert clock.may_advance(9)  # the grant of a client that left still runs to its end
    assert clock.abandon() == "q1" and clock.abandon() is None
    assert clock.request("b", 1, 10, "q4") == 11
    with pytest.raises(StepRefused, match=">= 1"):
        SteppedClock[str]().request("c", 0, 0, "q")


# ---------------------------------------------------------------------------- a real world
CONTROL_HZ = 120


def _scenario(tmp: Path, mode: str, world: str) -> Path:
    sc: Scenario = load_scenario()
    sc = msgspec.structs.replace(
        sc,
        world=msgspec.structs.replace(sc.world, name=world),
        vehicles=sc.vehicles[:1],
        time=msgspec.structs.replace(sc.time, mode=mode, control_hz=CONTROL_HZ),
    )
    return write_scenario(sc, tmp / f"{world}.toml")


class Stepped:
    def __init__(self, net: Network, sw: Swarm) -> None:
        self.net = net
        self.sw = sw
        self.states: dict[int, VehicleState] = {}
        self.statuses: list[VehicleStatus] = []
        sw.subscribe(on_state=partial(_keep_first, self.states), on_status=self.statuses.append)


@pytest.fixture(scope="module")
def stepped(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Stepped]:
    """Physics and one autopilot of a stepped world (no plume: readings are unavailable, which
    the clock does not care about), and a Swarm client that has not stepped yet."""
    tmp = tmp_path_factory.mktemp("stepped")
    path = _scenario(tmp, "stepped", "default")
    with zenoh_network() as (net, _router), NodeProcs(net, path, tmp) as procs:
        procs.start("autopilot", "--vehicle", "uav1")
        procs.start("physics")
        with Swarm.connect(connect=[net.endpoint], command_timeout_s=20.0) as sw:
            # the physics publishes its clock once its start handshake is done
            wait_until(_sim_time_or_none(sw), 120.0, "the stepped world's clock")
            yield Stepped(net, sw)


def test_step_pauses_the_world_at_the_granted_tick(stepped: Stepped) -> None:
    sw = stepped.sw
    with pytest.raises(ValueError, match="ticks must be an integer >= 1"):
        sw.step(0)
    reply = sw.step(10)  # from tick 0, where the world waits after its start handshake
    assert reply.tick == 10
    assert reply.sim_time_s == pytest.approx(10 / CONTROL_HZ, rel=1e-12)
    assert sw.sim_time == reply.sim_time_s and sw.holds_clock
    assert max(stepped.states) == 10 and sw.state("uav1").tick == 10
    # paused: nothing moves however long we wait
    with pytest.raises(WaitTimeout):
        sw.wait_until(lambda: max(stepped.states) > 10, timeout_s=0.5)
    assert sw.step(5).tick == 15


def test_step_until_stops_on_the_first_tick_that_holds(stepped: Stepped) -> None:
    sw = stepped.sw
    sw.command("uav1").arm()
    sw.command("uav1").takeoff(5.0)

    def above_1m() -> bool:
        return sw.state("uav1").position_enu_m[2] > 1.0

    reply_tick = sw.step_until(lambda: above_1m() and sw.state("uav1").tick, 30.0, "1 m up")
    states = stepped.states
    assert states[reply_tick].position_enu_m[2] > 1.0 >= states[reply_tick - 1].position_enu_m[2]
    before = sw.sim_time
    with pytest.raises(WaitTimeout, match=r"0\.05 s of sim time waiting for never"):
        sw.step_until(lambda: False, 0.05, "never")
    # ceil(0.05 s x 120 Hz) = 6 ticks, checked one at a time
    ticks = math.ceil(0.05 * CONTROL_HZ - 1e-9)
    assert sw.sim_time == pytest.approx(before + ticks / CONTROL_HZ, rel=1e-9)
    # a sim-time wait of the clock's holder steps the world
    start = sw.sim_time
    sw.wait_until(lambda: sw.sim_time >= start + 0.1, sim_timeout_s=1.0)
    assert sw.sim_time == pytest.approx(start + 0.1, abs=0.5 / CONTROL_HZ)
    with pytest.raises(ValueError, match=r"timeout_s .* or sim_timeout_s"):
        sw.wait_until(lambda: True)


def test_one_client_holds_the_clock_until_it_closes(stepped: Stepped) -> None:
    sw = stepped.sw
    sw.step(1)  # holds it
    with Swarm.connect(connect=[stepped.net.endpoint], command_timeout_s=20.0) as other:
        with pytest.raises(ClockError, match=r"refused \(client\): the clock is held by clock-"):
            other.step(1)
        assert not other.holds_clock
        sw.close()  # its token goes: the clock is free
        tick = wait_until(_step_or_none(other), 30.0, "the clock to be free")
        assert tick > 1


def _keep_first(states: dict[int, VehicleState], state: VehicleState) -> None:
    states.setdefault(state.tick, state)


def _sim_time_or_none(sw: Swarm) -> Callable[[], float | None]:
    def attempt() -> float | None:
        try:
            return sw.sim_time + 1.0  # truthy at t = 0 too
        except ClockError:
            return None

    return attempt


def _step_or_none(sw: Swarm) -> Callable[[], int | None]:
    def attempt() -> int | None:
        try:
            return sw.step(1).tick
        except ClockError:
            return None

    return attempt


def test_stepping_a_free_running_world_or_none_says_why(tmp_path: Path) -> None:
    path = _scenario(tmp_path, "lockstep", "free")
    with zenoh_network() as (net, _router), NodeProcs(net, path, tmp_path) as procs:
        procs.start("physics", "--set", "wait_for_autopilots=false")
        with Swarm.connect("free", [net.endpoint], command_timeout_s=20.0) as sw:
            wait_until(_sim_time_or_none(sw), 60.0, "the free world's clock")
            with pytest.raises(ClockError, match=r"refused \(mode\).*lockstep mode, not stepped"):
                sw.step(1)
            assert not sw.holds_clock
            # a sim-time wait of a free-running world watches its clock
            start = sw.sim_time
            with pytest.raises(WaitTimeout, match=r"0\.2 s of sim time"):
                sw.wait_until(lambda: False, 60.0, sim_timeout_s=0.2)
            assert sw.sim_time >= start + 0.2
        nobody = r"nobody serves clock/step\): is the physics of world 'nobody' running"
        with (
            Swarm.connect("nobody", [net.endpoint], command_timeout_s=2.0) as sw,
            pytest.raises(ClockError, match=nobody),
        ):
            sw.step(1, timeout_s=2.0)


# ---------------------------------------------------------------------------- the landing tick
LAND_AT = 360  # 3 s: in the air, climbing to or holding 3 m


def _fly(tmp: Path, land_at: int | None) -> dict[int, VehicleState]:
    """Take off at tick 1, optionally command a landing while paused at ``land_at``, run to
    ``LAND_AT + 4``; every state seen."""
    tmp.mkdir()
    path = _scenario(tmp, "stepped", "default")
    states: dict[int, VehicleState] = {}
    with zenoh_network() as (net, _router), NodeProcs(net, path, tmp) as procs:
        procs.start("autopilot", "--vehicle", "uav1")
        procs.start("physics")
        with Swarm.connect(connect=[net.endpoint], command_timeout_s=20.0) as sw:
            wait_until(_sim_time_or_none(sw), 120.0, "the stepped world's clock")
            sw.subscribe(on_state=partial(_keep_first, states))
            uav = sw.command("uav1")
            sw.step(1)
            uav.arm()
            uav.takeoff(3.0)
            sw.step(LAND_AT - 1)
            if land_at is not None:
                uav.land()
            sw.step(4)
            mode = sw.status("uav1").mode
            assert mode == FlightMode.LAND if land_at is not None else mode == FlightMode.HOLD
    return states


def test_a_command_between_steps_lands_on_the_next_tick(tmp_path: Path) -> None:
    """Paused at tick T the autopilot has answered T; a command it accepts now is used by its
    control step of tick T+1, whose motor commands act from T+1 to T+2. So the same script with
    and without a Land at T gives the same states, bit for bit, up to T+1, and different ones
    from T+2 on (never later, however long the command took)."""
    plain = _fly(tmp_path / "plain", None)
    landed = _fly(tmp_path / "land", LAND_AT)
    assert not plain[LAND_AT].on_ground and plain[LAND_AT].position_enu_m[2] > 1.0
    common = sorted(t for t in set(plain) & set(landed) if t <= LAND_AT + 1)
    assert common[0] <= 10 and common[-1] == LAND_AT + 1 and len(common) > LAND_AT - 10
    for t in common:
        assert plain[t] == landed[t], f"tick {t} differs before the command could act"
    for t in (LAND_AT + 2, LAND_AT + 3):
        assert plain[t] != landed[t], f"the landing did not act by tick {t}"
    # the landing pulls down: less upward velocity than the plain climb or hold
    assert landed[LAND_AT + 3].velocity_enu_m_s[2] < plain[LAND_AT + 3].velocity_enu_m_s[2]


def test_up_stepped_waits_for_a_client_to_step_it(tmp_path: Path) -> None:
    """``plumeswarm up --stepped``: every process flies the stepped copy of the scenario, and
    the world stays at tick 0 until a Swarm steps it."""
    roles = "router,plume,physics,autopilot"
    with plumeswarm_up(None, tmp_path, "--headless", "--stepped", "--roles", roles) as up:
        stepped_toml = up.run / "scenario-stepped.toml"
        assert load_scenario(stepped_toml).time.mode == "stepped"
        with Swarm.connect(connect=[up.endpoint], command_timeout_s=20.0) as sw:
            wait_until(_sim_time_or_none(sw), 120.0, "the stepped world's clock")
            assert sw.sim_time == 0.0
            reply = sw.step(3)
            assert reply.tick == 3 and sw.vehicles == ["uav1", "uav2", "uav3"]
            assert {sw.state(v).tick for v in sw.vehicles} == {3}
