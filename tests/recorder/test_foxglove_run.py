"""Foxglove on a short real run: ``plumeswarm up --record --foxglove`` flying the bundled
scenario's missions. A WebSocket client speaking the SDK's Foxglove protocol gets the advertised
channels and their messages while the swarm flies; the recording opens with the mcap library and
every Foxglove channel decodes against the schema the foxglove SDK declares;
``plumeswarm export foxglove`` on that recording makes the same Foxglove messages again."""

from __future__ import annotations

import base64
import itertools
import json
import socket
import struct
import time
from collections import defaultdict
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from agents import VehicleCommander
from deploy.launcher import LaunchOptions, plan
from recorder.foxglove.layout import layout_json
from recorder.reader import Recording
from swarmbus.messages import Arm, MissionStart, MissionUpload, SimTick
from swarmbus.scenario import load_scenario, resolve_scenario_path
from swarmbus.session import NetworkConfig, free_tcp_port, open_session
from tests.support.foxglove_decode import ChannelDecoder
from tests.support.procs import NODE_COMMAND, keys_for, run_cli
from tests.support.upstack import plumeswarm_up

SUBPROTOCOL = "foxglove.sdk.v1"  # the Foxglove WebSocket protocol (v1) as the SDK's server names it
LIVE_TIMEOUT_S = 120.0
FLYING_M = 3.0  # a vehicle this high above its spawn is flying


@dataclass
class Live:
    channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    decoded: dict[str, list[Any]] = field(default_factory=lambda: defaultdict(list))
    max_z_m: float = 0.0


@dataclass
class Run:
    live: Live
    recording: Path


def wanted_topics(vehicle_ids: list[str]) -> set[str]:
    return {
        "/tf",
        "/scene/vehicles",
        "/scene/plume",
        "/scene/readings",
        "/scene/trails",
        *(f"/location/{v}" for v in vehicle_ids),
        *(f"/concentration/{v}" for v in vehicle_ids),
    }


def watch_live(port: int, vehicle_ids: list[str], fly: Any) -> Live:
    """Connect, subscribe to every advertised channel, decode what arrives until every wanted
    topic has messages and a vehicle is seen flying (``fly`` starts the missions once)."""
    live = Live()
    decoder = ChannelDecoder()
    subs: dict[int, int] = {}  # subscription id → channel id
    wanted = wanted_topics(vehicle_ids)
    deadline = time.monotonic() + LIVE_TIMEOUT_S
    flown = False
    with connect(
        f"ws://127.0.0.1:{port}", subprotocols=[Subprotocol(SUBPROTOCOL)], open_timeout=30
    ) as ws:
        assert ws.subprotocol == SUBPROTOCOL
        while True:
            have = {t for t, msgs in live.decoded.items() if msgs}
            if wanted <= have and live.max_z_m > FLYING_M:
                return live
            assert time.monotonic() < deadline, (
                f"live Foxglove: no messages on {sorted(wanted - have)} "
                f"(highest vehicle {live.max_z_m:.1f} m) within {LIVE_TIMEOUT_S} s"
            )
            if not flown and "/tf" in have:
                fly()
                flown = True
            try:
                frame = ws.recv(timeout=1.0)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    new = []
                    for ch in msg["channels"]:
                        live.channels[ch["id"]] = ch
                        subs[len(subs) + 1] = ch["id"]
                        new.append({"id": len(subs), "channelId": ch["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                continue
            assert frame[0] == 0x01, f"unexpected binary opcode {frame[0]}"  # message data
            sub_id, _log_time_ns = struct.unpack_from("<IQ", frame, 1)
            ch = live.channels[subs[sub_id]]
            schema = ch["schema"]
            data = base64.b64decode(schema) if ch["schemaEncoding"] == "protobuf" else schema
            value = decoder.decode(
                ch["schemaName"], ch["schemaEncoding"], data.encode() if isinstance(data, str)
                else data, bytes(frame[13:]),
            )  # fmt: skip
            live.decoded[ch["topic"]].append(value)
            if ch["topic"] == "/tf":
                live.max_z_m = max([live.max_z_m, *(t.translation.z for t in value.transforms)])


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Run]:
    tmp = tmp_path_factory.mktemp("foxglove")
    sc = load_scenario(resolve_scenario_path(None))
    ids = [v.id for v in sc.vehicles]
    port = free_tcp_port()
    args = ["--headless", "--record", "--foxglove", "--foxglove-port", str(port)]
    with plumeswarm_up(None, tmp, *args) as up:
        net = NetworkConfig(connect=[up.endpoint], listen=[])
        with open_session(net) as session:

            def fly() -> None:
                deadline = time.monotonic() + 60.0
                for v in sc.vehicles:
                    for cmd in (MissionUpload(items=v.mission), Arm(), MissionStart()):
                        VehicleCommander(session, keys_for(), v.id, 5.0).send(
                            cmd, retry_until=deadline
                        )

            live = watch_live(port, ids, fly)
    yield Run(live=live, recording=up.run / "recording.mcap")


def test_live_client_gets_the_advertised_channels_and_messages_while_flying(run: Run) -> None:
    sc = load_scenario(resolve_scenario_path(None))
    ids = {v.id for v in sc.vehicles}
    by_topic = {ch["topic"]: ch for ch in run.live.channels.values()}
    assert by_topic["/tf"]["schemaName"] == "foxglove.FrameTransforms"
    assert by_topic["/scene/plume"]["schemaName"] == "foxglove.SceneUpdate"
    assert by_topic[f"/location/{sorted(ids)[0]}"]["schemaName"] == "foxglove.LocationFix"
    tf = run.live.decoded["/tf"][-1]
    assert {t.child_frame_id for t in tf.transforms} == ids
    plume = run.live.decoded["/scene/plume"][-1]
    assert any(e.id.startswith("plume/level_") and e.triangles for e in plume.entities)
    fixes = run.live.decoded[f"/location/{sorted(ids)[0]}"]
    assert all(abs(f.latitude - sc.world.origin.lat_deg) < 0.01 for f in fixes)


def foxglove_messages(path: Path) -> dict[str, list[tuple[int, bytes]]]:
    """Every message of the Foxglove channels of ``path``, by topic, decoded (checked against
    the SDK's schema) and kept as (log time, bytes)."""
    decoder = ChannelDecoder()
    out: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            if channel.metadata.get("origin") != "foxglove":
                continue
            assert schema is not None, channel.topic
            decoder.decode(schema.name, schema.encoding, schema.data, message.data)
            out[channel.topic].append((message.log_time, message.data))
    return out


def recorded_ticks(path: Path) -> list[SimTick]:
    ticks = []
    for rec in Recording.open(path).messages():
        msg = rec.message()
        if isinstance(msg, SimTick):
            ticks.append(msg)
    return ticks


def test_recording_holds_foxglove_channels_that_decode_and_scrub_in_sim_time(run: Run) -> None:
    sc = load_scenario(resolve_scenario_path(None))
    ids = [v.id for v in sc.vehicles]
    fox = foxglove_messages(run.recording)
    assert wanted_topics(ids) <= set(fox)
    # Stamped in simulation time: /tf at 20 Hz of it, so consecutive stamps 50 ms apart (a
    # multiple of it where ticks were lost on the way), spanning the sim time the ticks span.
    stamps = [t for t, _ in fox["/tf"]]
    steps = [round((b - a) / 1e6) for a, b in itertools.pairwise(stamps)]
    assert steps and all(step > 0 and step % 50 == 0 for step in steps), sorted(set(steps))[:10]
    sim = [m.sim_time_s for m in recorded_ticks(run.recording)]
    assert abs((stamps[-1] - stamps[0]) / 1e9 - (sim[-1] - sim[0])) <= 0.05 + 1e-9


def test_export_foxglove_makes_the_same_foxglove_messages_again(run: Run, tmp_path: Path) -> None:
    out = tmp_path / "exported.mcap"
    layout = tmp_path / "layout.json"
    res = run_cli(["export", "foxglove", str(run.recording), str(out), "--layout", str(layout)])
    assert res.returncode == 0, res.stderr
    sc = load_scenario(resolve_scenario_path(None))
    assert json.loads(layout.read_text()) == json.loads(layout_json([v.id for v in sc.vehicles]))
    assert "Foxglove messages" in res.stderr
    assert foxglove_messages(out) == foxglove_messages(run.recording)
    with open(out, "rb") as f, open(run.recording, "rb") as g:
        exported = make_reader(f).get_summary()
        original = make_reader(g).get_summary()
    assert exported is not None and original is not None
    assert exported.statistics is not None and original.statistics is not None
    assert exported.statistics.message_count == original.statistics.message_count


def test_export_foxglove_refuses_a_missing_input_in_one_line(tmp_path: Path) -> None:
    res = run_cli(["export", "foxglove", str(tmp_path / "nope.mcap"), str(tmp_path / "o.mcap")])
    assert res.returncode == 2
    assert res.stderr.strip().splitlines() == [
        f"plumeswarm: error: {tmp_path / 'nope.mcap'}: no such file"
    ]


def test_a_taken_port_is_one_clear_error(tmp_path: Path) -> None:
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
        res = run_cli(["node", "foxglove", "--connect", endpoint, "--set", f"port={port}"], 60.0)
    assert res.returncode == 2
    assert f"cannot serve on 127.0.0.1:{port}" in res.stderr
    assert "--set port=N" in res.stderr and "Traceback" not in res.stderr


def test_a_bad_option_is_one_clear_error() -> None:
    res = run_cli(["node", "foxglove", "--set", "port=http"], 60.0)
    assert res.returncode == 2
    assert (
        "--set port=http: expected an integer in [0, 65535]" in res.stderr
        and "Traceback" not in res.stderr
    )


def test_up_runs_the_foxglove_role_only_when_asked() -> None:
    path = resolve_scenario_path(None)
    sc = load_scenario(path)
    off = plan(sc, LaunchOptions(node_command=NODE_COMMAND, scenario_path=path, headless=True))
    assert "foxglove" not in {s.role for s in off}
    on = plan(sc, LaunchOptions(
        node_command=NODE_COMMAND, scenario_path=path, foxglove=True,
        node_options={"foxglove": ("port=9876",)},
    ))  # fmt: skip
    spec = next(s for s in on if s.role == "foxglove")
    assert spec.argv[-2:] == ("--set", "port=9876") and not spec.critical
