"""Decoding Foxglove channels the way Foxglove does: by the schema each channel declares, in its
own encoding (protobuf descriptors through ``mcap-protobuf-support``, JSON through JSON Schema),
and comparing that schema with the one the foxglove SDK declares for the type."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jsonschema
import msgspec
from foxglove import messages as fm
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_protobuf.decoder import DecoderFactory

SDK_TYPES = {t.get_schema().name: t for t in (fm.FrameTransforms, fm.SceneUpdate, fm.LocationFix)}


class ChannelDecoder:
    """Decodes messages of channels given their schema (name, encoding, bytes)."""

    def __init__(self) -> None:
        self._factory = DecoderFactory()
        self._ids: dict[tuple[str, bytes], int] = {}

    def decode(
        self, schema_name: str, schema_encoding: str, schema_data: bytes, data: bytes
    ) -> Any:
        if schema_encoding == "protobuf":
            sdk = SDK_TYPES[schema_name]  # KeyError: not one of the well-known schemas we use
            assert schema_data == bytes(sdk.get_schema().data), f"{schema_name}: not the SDK's"
            sid = self._ids.setdefault((schema_name, schema_data), len(self._ids) + 1)
            schema = Schema(id=sid, name=schema_name, encoding="protobuf", data=schema_data)
            decoder = self._factory.decoder_for("protobuf", schema)
            assert decoder is not None
            return decoder(data)
        assert schema_encoding == "jsonschema", schema_encoding
        value = msgspec.json.decode(data)
        jsonschema.validate(value, msgspec.json.decode(schema_data))
        return value


def topic_messages(path: Path, topic: str) -> list[tuple[int, Any]]:
    """The messages on ``topic`` of the MCAP file ``path``, (log time, decoded), in file order."""
    decoder = ChannelDecoder()
    with open(path, "rb") as f:
        return [
            (message.log_time, decoder.decode(schema.name, schema.encoding, schema.data,
                                              message.data))
            for schema, channel, message in make_reader(f).iter_messages(log_time_order=False)
            if channel.topic == topic and schema is not None
        ]  # fmt: skip
