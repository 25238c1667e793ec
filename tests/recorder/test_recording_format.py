"""The MCAP layout (no network): what standard MCAP readers see in a recorder's file."""

from __future__ import annotations

import json
from pathlib import Path

import msgspec
from mcap.reader import make_reader

from recorder import schema as sch
from recorder.reader import Recording
from recorder.sink import McapSink
from swarmbus.codec import encode
from swarmbus.keys import Keys
from swarmbus.messages import ALL_MESSAGES, FlightMode, PlumeMesh, VehicleStatus

KEYS = Keys()


def test_every_message_type_has_a_self_contained_json_schema() -> None:
    for type_ in ALL_MESSAGES:
        schema = json.loads(sch.json_schema(type_))
        assert schema["type"] == "object", type_
        assert "$ref" not in json.dumps(schema), type_
        assert sch.schema_name(type_) == f"plumeswarm.{type_.__name__}"


def test_json_storage_round_trips_bytes_and_enums() -> None:
    mesh = PlumeMesh(level_g_m3=0.01, vertices_f32=b"\x00\x01\xff", faces_i32=b"")
    status = VehicleStatus(vehicle_id="uav1", sim_time_s=1.5, mode=FlightMode.RTL, armed=True,
                           landed=False)  # fmt: skip
    for message in (mesh, status):
        stored = sch.to_json(sch.decode_bus(encode(message)))
        assert json.loads(stored)["schema"] == type(message).__struct_config__.tag
        assert sch.from_json(stored) == message


def test_standard_reader_sees_schemas_channels_and_index(tmp_path: Path) -> None:
    path = tmp_path / "f.mcap"
    sink = McapSink(path, metadata={"world": "default"})
    status = VehicleStatus(vehicle_id="uav1", sim_time_s=0.0, mode=FlightMode.HOLD, armed=True,
                           landed=False)  # fmt: skip
    for i in range(5):
        sink.write_bus(KEYS.vehicle_status("uav1"), encode(status), 1_000 + i)
    sink.write_bus(KEYS.vehicle_status("uav1"), b"\xc1junk", 2_000)
    sink.close({"received_total": "6"})

    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        # 6 bus messages + the "undecodable" event
        assert summary.statistics is not None and summary.statistics.message_count == 7
        assert len(summary.chunk_indexes) >= 1
        schemas = {s.name: s.encoding for s in summary.schemas.values()}
        assert schemas == {
            "plumeswarm.VehicleStatus": "jsonschema",
            "plumeswarm.RecorderEvent": "jsonschema",
        }
        channels = sorted((c.topic, c.message_encoding) for c in summary.channels.values())
        assert channels == [
            (KEYS.vehicle_status("uav1"), "application/octet-stream"),
            (KEYS.vehicle_status("uav1"), "json"),
            ("recorder/events", "json"),
        ]
        messages = list(reader.iter_messages(topics=[KEYS.vehicle_status("uav1")]))
        assert [m.log_time for _, _, m in messages] == [1_000, 1_001, 1_002, 1_003, 1_004, 2_000]
        assert msgspec.json.decode(messages[0][2].data)["mode"] == "hold"
    recording = Recording.open(path)
    assert recording.message_count == 7
    assert [m.message() for m in recording.messages()][:5] == [status] * 5


def test_a_file_cut_anywhere_reads_to_its_last_complete_chunk(tmp_path: Path) -> None:
    path = tmp_path / "f.mcap"
    sink = McapSink(path, chunk_interval_s=0.0)  # a chunk per message
    status = VehicleStatus(vehicle_id="uav1", sim_time_s=0.0, mode=FlightMode.HOLD, armed=True,
                           landed=False)  # fmt: skip
    for i in range(20):
        sink.write_bus(KEYS.vehicle_status("uav1"), encode(status), i)
        sink.maybe_close_chunk()
    sink.close()
    data = path.read_bytes()
    counts = []
    for cut in range(len(data) // 2, len(data), 97):
        (tmp_path / "cut.mcap").write_bytes(data[:cut])
        recording = Recording.open(tmp_path / "cut.mcap")
        counts.append(sum(1 for _ in recording.messages()))
        assert recording.truncated
    assert counts == sorted(counts) and counts[-1] == 20
