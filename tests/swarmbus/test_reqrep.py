"""Request/reply (``swarmbus.reqrep``) between two real Zenoh sessions on loopback: the reply, a
refusal naming the field, no reply, a malformed request, and the non-blocking variant."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator

import msgspec
import pytest
import zenoh

from agents import CommandRejected, Swarm, VehicleCommander
from plumeswarm.experiments.demo import DemoError, start_missions
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import (
    Command,
    CommandReply,
    Goto,
    Hold,
    PlumeInfoQuery,
    PlumeQuery,
    PlumeValues,
    RejectCode,
)
from swarmbus.reqrep import (
    BadReply,
    Incoming,
    NoReply,
    Refused,
    RequestError,
    ask,
    command_reply,
    request,
    serve,
    serve_later,
)
from swarmbus.scenario import load_scenario
from swarmbus.session import open_session
from tests.support.procs import Network

KEYS = Keys("reqrep")
KEY = KEYS.plume_concentration()
ROUTE_DEADLINE_S = 20.0


def sums(query: PlumeQuery) -> PlumeValues:
    """A handler whose answer is easy to derive by hand: x + y + z of each point."""
    if any(z < 0.0 for _, _, z in query.points_enu_m):
        bad = next(i for i, p in enumerate(query.points_enu_m) if p[2] < 0.0)
        raise Refused(f"points_enu_m[{bad}]", "below ground")
    return PlumeValues(values_g_m3=[x + y + z for x, y, z in query.points_enu_m])


def counting(calls: list[PlumeQuery]) -> Callable[[PlumeQuery], PlumeValues]:
    """:func:`sums` that notes each request it sees in ``calls``."""

    def handler(query: PlumeQuery) -> PlumeValues:
        calls.append(query)
        return sums(query)

    return handler


@pytest.fixture
def pair(network: tuple[Network, zenoh.Session]) -> Iterator[tuple[zenoh.Session, zenoh.Session]]:
    """(server, client): the router's session serves, a second session asks."""
    net, server = network
    with open_session(net.client) as client:
        yield server, client


Handler = Callable[[PlumeQuery], object]
Serving = Callable[..., zenoh.Session]


@pytest.fixture
def serving(pair: tuple[zenoh.Session, zenoh.Session]) -> Iterator[Serving]:
    """``serving(handler, memo=False)`` serves ``KEY`` with ``handler`` on the server session
    and gives the client session; the queryable goes at the end of the test."""
    server, client = pair
    queryables: list[zenoh.Queryable[None]] = []

    def start(handler: Handler, *, memo: bool = False) -> zenoh.Session:
        queryables.append(serve(server, KEY, PlumeQuery, handler, memo=memo))
        return client

    yield start
    for q in queryables:
        q.undeclare()


def first_answer(client: zenoh.Session, payload: object, reply_type: type[object]) -> object:
    """Ask until the queryable is routed to the client (it reaches a new session shortly after
    it is declared); the reply or the refusal."""
    deadline = time.monotonic() + ROUTE_DEADLINE_S
    while True:
        outcome = ask(client, KEY, payload, reply_type, 5.0).outcome()
        if not isinstance(outcome, NoReply):
            return outcome
        assert time.monotonic() < deadline, f"no route to {KEY}: {outcome}"
        time.sleep(0.05)


def test_a_request_gets_the_typed_reply(serving: Serving) -> None:
    client = serving(sums)
    query = PlumeQuery(points_enu_m=[(1.0, 2.0, 3.0), (10.0, -4.0, 0.5)])
    first = first_answer(client, query, PlumeValues)
    again = request(client, KEY, query, PlumeValues, 5.0)
    assert first == again == PlumeValues(values_g_m3=[6.0, 6.5])
    pending = ask(client, KEY, query, PlumeValues, 5.0)  # polled, never blocking
    deadline = time.monotonic() + 10.0
    while not pending.done():
        assert time.monotonic() < deadline, "no answer to a polled request"
        time.sleep(0.01)
    assert pending.result() == first and pending.answered


def test_a_handler_refusal_names_the_field(serving: Serving) -> None:
    client = serving(sums)
    first_answer(client, PlumeQuery(points_enu_m=[(0.0, 0.0, 1.0)]), PlumeValues)
    with pytest.raises(Refused) as refused:
        query = PlumeQuery(points_enu_m=[(0.0, 0.0, 1.0), (5.0, 5.0, -2.0)])
        request(client, KEY, query, PlumeValues, 5.0)
    assert refused.value.field == "points_enu_m[1]"
    assert refused.value.reason == "below ground"
    assert refused.value.key == KEY and KEY in str(refused.value)


def test_a_plain_value_error_is_a_refusal_of_the_whole_request(serving: Serving) -> None:
    def picky(query: PlumeQuery) -> PlumeValues:
        raise ValueError("no points today")

    client = serving(picky)
    outcome = first_answer(client, PlumeQuery(points_enu_m=[]), PlumeValues)
    assert isinstance(outcome, Refused)
    assert (outcome.field, outcome.reason) == ("", "no points today")


def test_a_malformed_request_is_refused_naming_the_field(serving: Serving) -> None:
    calls: list[PlumeQuery] = []
    client = serving(counting(calls))
    first_answer(client, PlumeQuery(points_enu_m=[]), PlumeValues)
    calls.clear()
    # A NaN coordinate (the struct's bounds reject it), written without the struct's checks.
    nan = msgspec.msgpack.encode(
        {"schema": "plume_query/v1", "points_enu_m": [[0.0, 0.0, 1.0], [1.0, float("nan"), 2.0]]}
    )
    with pytest.raises(Refused) as refused:
        request(client, KEY, nan, PlumeValues, 5.0)
    assert refused.value.field == "points_enu_m[1][1]"
    with pytest.raises(Refused) as wrong:
        request(client, KEY, PlumeInfoQuery(), PlumeValues, 5.0)  # another message entirely
    assert wrong.value.field == "schema"
    with pytest.raises(Refused) as garbage:
        request(client, KEY, b"\xc1\xff\x00", PlumeValues, 5.0)
    assert garbage.value.field == "" and garbage.value.reason
    assert calls == [], "the handler saw a request that does not decode"
    # and it keeps serving
    ok = request(client, KEY, PlumeQuery(points_enu_m=[(1.0, 1.0, 1.0)]), PlumeValues, 5.0)
    assert ok.values_g_m3 == [3.0]


def test_no_server_or_a_silent_one_is_no_reply(
    pair: tuple[zenoh.Session, zenoh.Session],
) -> None:
    server, client = pair
    t0 = time.monotonic()
    with pytest.raises(NoReply) as nobody:
        request(client, KEYS.plume_info(), PlumeInfoQuery(), PlumeValues, 30.0)
    assert nobody.value.key == KEYS.plume_info()
    assert time.monotonic() - t0 < 30.0, "nothing serves the key: the answer is at once"
    held: list[Incoming[PlumeQuery]] = []
    q = serve_later(server, KEY, PlumeQuery, held.append)
    deadline = time.monotonic() + ROUTE_DEADLINE_S
    while not held:  # until the queryable is routed: then it holds the request unanswered
        with pytest.raises(NoReply):
            request(client, KEY, PlumeQuery(points_enu_m=[]), PlumeValues, 0.3)
        assert time.monotonic() < deadline, "the queryable never got a request"
    t0 = time.monotonic()
    with pytest.raises(NoReply) as silent:
        request(client, KEY, PlumeQuery(points_enu_m=[]), PlumeValues, 0.5)
    waited = time.monotonic() - t0
    assert silent.value.timeout_s == 0.5 and waited >= 0.5
    assert isinstance(silent.value, TimeoutError)
    for incoming in held:
        incoming.drop()
    q.undeclare()


def test_a_reply_of_the_wrong_type_is_a_bad_reply(serving: Serving) -> None:
    client = serving(lambda query: PlumeInfoQuery())
    outcome = first_answer(client, PlumeQuery(points_enu_m=[]), PlumeValues)
    assert isinstance(outcome, BadReply) and outcome.field == "schema"


def test_a_failing_handler_leaves_no_reply_and_the_server_goes_on(serving: Serving) -> None:
    def flaky(query: PlumeQuery) -> PlumeValues:
        if not query.points_enu_m:
            raise RuntimeError("a bug")
        return sums(query)

    client = serving(flaky)
    first_answer(client, PlumeQuery(points_enu_m=[(1.0, 0.0, 0.0)]), PlumeValues)
    with pytest.raises(NoReply):
        request(client, KEY, PlumeQuery(points_enu_m=[]), PlumeValues, 5.0)
    ok = request(client, KEY, PlumeQuery(points_enu_m=[(2.0, 0.0, 0.0)]), PlumeValues, 5.0)
    assert ok.values_g_m3 == [2.0]


def test_memo_answers_a_repeated_request_without_the_handler(serving: Serving) -> None:
    calls: list[PlumeQuery] = []
    client = serving(counting(calls), memo=True)
    same = PlumeQuery(points_enu_m=[(1.0, 2.0, 3.0)])
    first_answer(client, same, PlumeValues)
    n = len(calls)
    for _ in range(3):
        assert request(client, KEY, same, PlumeValues, 5.0).values_g_m3 == [6.0]
    assert len(calls) == n, "the same request computed again"
    other = PlumeQuery(points_enu_m=[(1.0, 2.0, 4.0)])
    assert request(client, KEY, other, PlumeValues, 5.0).values_g_m3 == [7.0]
    assert len(calls) == n + 1
    # only the previous request is remembered: the first one is computed again
    assert request(client, KEY, same, PlumeValues, 5.0).values_g_m3 == [6.0]
    assert len(calls) == n + 2


def test_ask_does_not_block_and_calls_back_once(
    pair: tuple[zenoh.Session, zenoh.Session],
) -> None:
    """A server answering later from another thread; the client's callback gets each outcome
    once, and ``ask`` returns before the answer exists."""
    server, client = pair
    held: list[Incoming[PlumeQuery]] = []
    arrived = threading.Condition()

    def hold(incoming: Incoming[PlumeQuery]) -> None:
        with arrived:
            held.append(incoming)
            arrived.notify_all()

    q = serve_later(server, KEY, PlumeQuery, hold)
    deadline = time.monotonic() + ROUTE_DEADLINE_S
    outcomes: list[PlumeValues | RequestError] = []
    done = threading.Event()

    def on_done(outcome: PlumeValues | RequestError) -> None:
        with arrived:
            outcomes.append(outcome)
            done.set()
            arrived.notify_all()

    while True:  # until the queryable is routed to the client and holds a request
        query = PlumeQuery(points_enu_m=[(1.0, 1.0, 2.0)])
        pending = ask(client, KEY, query, PlumeValues, 10.0, on_done)
        with arrived:
            arrived.wait_for(lambda: bool(held) or done.is_set(), 12.0)
            if held:
                break
        assert time.monotonic() < deadline, "the queryable never got a request"
        outcomes.clear()
        done.clear()
        time.sleep(0.05)
    assert not pending.done() and outcomes == [], "answered before the server replied"
    answer: Callable[[PlumeQuery], PlumeValues] = sums
    threading.Thread(target=held[0].answer, args=(answer,)).start()
    assert done.wait(10.0), "no callback"
    assert pending.done() and pending.result() == PlumeValues(values_g_m3=[4.0])
    time.sleep(0.2)  # a second call would come right after the first: there is none
    assert outcomes == [PlumeValues(values_g_m3=[4.0])]
    # refusing later works the same
    pending = ask(client, KEY, PlumeQuery(points_enu_m=[]), PlumeValues, 10.0)
    with arrived:
        assert arrived.wait_for(lambda: len(held) == 2, 10.0)
    held[1].refuse("ticks", "not now")
    outcome = pending.outcome()
    assert isinstance(outcome, Refused) and (outcome.field, outcome.reason) == ("ticks", "not now")
    q.undeclare()


def test_a_closed_session_is_no_reply_not_a_crash(network: tuple[Network, zenoh.Session]) -> None:
    net, _ = network
    session = open_session(net.client)
    session.close()
    calls: list[object] = []
    pending = ask(session, KEY, encode(PlumeQuery(points_enu_m=[])), PlumeValues, 1.0, calls.append)
    assert isinstance(pending.outcome(), NoReply) and len(calls) == 1


def test_a_refused_command_reads_the_same_in_every_client(
    pair: tuple[zenoh.Session, zenoh.Session],
) -> None:
    """A command with a NaN coordinate, refused by a ``serve``d command queryable: the Swarm
    client, the gateway's and environments' mapping and the demo all name the field."""
    server, client = pair
    keys = Keys("default")
    taken: list[object] = []

    def accept_all(command: object) -> CommandReply:
        taken.append(command)
        return CommandReply(vehicle_id="uav1", accepted=True)

    q = serve(server, keys.vehicle_cmd("uav1"), Command, accept_all)  # type: ignore[arg-type]
    uav = VehicleCommander(client, keys, "uav1", 5.0)
    uav.send(Hold(), retry_until=time.monotonic() + ROUTE_DEADLINE_S)  # routed, and accepted
    nan = float("nan")
    with pytest.raises(CommandRejected) as rejected:
        uav.goto(1.0, 2.0, nan)
    assert rejected.value.code == RejectCode.INVALID
    assert rejected.value.field == "position_enu_m[2]" and rejected.value.reason

    goto = Goto(position_enu_m=(1.0, 2.0, nan))
    outcome = ask(client, keys.vehicle_cmd("uav1"), goto, CommandReply, 5.0).outcome()
    reply = command_reply("uav1", outcome)
    assert not reply.accepted and reply.code == RejectCode.INVALID
    assert reply.reason.startswith("position_enu_m[2]: ")

    sc = load_scenario()
    bad = msgspec.structs.replace(sc.vehicles[0].mission[0], z=nan)
    first = msgspec.structs.replace(sc.vehicles[0], mission=[bad])
    sc = msgspec.structs.replace(sc, vehicles=[first])
    sw = Swarm(client, keys, 5.0, own_session=False)
    with pytest.raises(
        DemoError, match=r"uav1: MissionUpload rejected \[invalid\] \(items\[0\]\.z\)"
    ):
        start_missions(sw, sc, time.monotonic() + 10.0)
    sw.close()
    assert [type(c) for c in taken] == [Hold], "the server took a command it should refuse"
    q.undeclare()
