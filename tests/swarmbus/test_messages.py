"""Every message round-trips; every decoder rejects garbage with a typed error naming the field."""

from __future__ import annotations

import contextlib
import logging
import math
from typing import Any

import msgspec
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmbus import messages as m
from swarmbus.codec import MessageError, decode, decode_or_none, encode
from tests.support.messages_samples import SAMPLES

ALL = list(m.ALL_MESSAGES)


def test_every_message_type_has_a_sample() -> None:
    assert set(SAMPLES) == set(ALL)


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_round_trip(cls: type[m.Message]) -> None:
    msg = SAMPLES[cls]
    data = encode(msg)
    assert isinstance(data, bytes)
    assert decode(data, cls) == msg


@pytest.mark.parametrize("cls", ALL, ids=lambda c: c.__name__)
def test_schema_tag_carries_version(cls: type[m.Message]) -> None:
    as_dict = msgspec.msgpack.decode(encode(SAMPLES[cls]))
    assert as_dict["schema"].endswith("/v1")
    as_dict["schema"] = as_dict["schema"][:-1] + "2"
    with pytest.raises(MessageError) as err:
        decode(msgspec.msgpack.encode(as_dict), cls)
    assert err.value.field == "schema"


def test_command_union_dispatches_by_tag() -> None:
    for cls in (m.Arm, m.Takeoff, m.MissionUpload, m.Setpoint, m.SetParam):
        assert type(decode(encode(SAMPLES[cls]), m.Command)) is cls  # type: ignore[arg-type]


def _mutated(cls: type[m.Message], field: str, value: object) -> bytes:
    d = msgspec.msgpack.decode(encode(SAMPLES[cls]))
    target = d
    path = field.split(".")
    for part in path[:-1]:
        target = target[int(part)] if part.isdigit() else target[part]
    last = path[-1]
    if last.isdigit():
        target[int(last)] = value
    else:
        target[last] = value
    return msgspec.msgpack.encode(d)


@pytest.mark.parametrize(
    ("cls", "field", "value", "expected_field"),
    [
        (m.VehicleState, "position_enu_m.2", math.nan, "position_enu_m[2]"),
        (m.VehicleState, "velocity_enu_m_s.0", math.inf, "velocity_enu_m_s[0]"),
        (m.VehicleState, "lat_deg", 91.0, "lat_deg"),
        (m.VehicleState, "vehicle_id", "a/b", "vehicle_id"),
        (m.VehicleState, "tick", -1, "tick"),
        (m.ActuatorCommand, "rotor_commands.1", 1.5, "rotor_commands[1]"),
        (m.ActuatorCommand, "tick", "7", "tick"),
        (m.ActuatorBatch, "commands.1.rotor_commands.0", -0.1, "commands[1].rotor_commands[0]"),
        (m.ActuatorBatch, "commands.0.vehicle_id", "uav/1", "commands[0].vehicle_id"),
        (m.ActuatorBatch, "tick", -1, "tick"),
        (m.Takeoff, "altitude_m", -3.0, "altitude_m"),
        (m.PlumeQuery, "points_enu_m.1.2", math.nan, "points_enu_m[1][2]"),
        (m.SimTick, "states.0.attitude_xyzw.3", math.inf, "states[0].attitude_xyzw[3]"),
        (m.MissionUpload, "items.0.x", math.nan, "items[0].x"),
        (m.SetParam, "value", math.nan, "value"),
        (m.SetMode, "mode", "acro", "mode"),
        (m.ConcentrationReading, "reported_g_m3", -1.0, "reported_g_m3"),
    ],
)
def test_bad_field_is_named(
    cls: type[m.Message], field: str, value: object, expected_field: str
) -> None:
    with pytest.raises(MessageError) as err:
        decode(_mutated(cls, field, value), cls)
    assert err.value.field == expected_field
    assert cls.__name__ in str(err.value)


def test_actuator_batch_length_is_bounded() -> None:
    one = m.ActuatorCommand(vehicle_id="uav1", tick=1, rotor_commands=[0.5] * 4)
    data = msgspec.msgpack.encode(
        {"schema": "actuator_batch/v1", "tick": 1, "commands": [one] * (m.MAX_BATCH_COMMANDS + 1)}
    )
    with pytest.raises(MessageError) as err:
        decode(data, m.ActuatorBatch)
    assert err.value.field == "commands"


def test_missing_field_is_named() -> None:
    d = msgspec.msgpack.decode(encode(SAMPLES[m.VehicleState]))
    del d["on_ground"]
    with pytest.raises(MessageError) as err:
        decode(msgspec.msgpack.encode(d), m.VehicleState)
    assert "on_ground" in err.value.reason


def test_garbage_is_a_typed_error() -> None:
    for junk in (b"", b"\xc1", b"\x93\x01\x02", b"not msgpack at all", b"\xff" * 50):
        with pytest.raises(MessageError):
            decode(junk, m.VehicleState)


def test_decode_or_none_gives_the_message_or_none_and_one_warning_naming_what_and_why(
    caplog: pytest.LogCaptureFixture,
) -> None:
    log = logging.getLogger("tests.decode_or_none")
    good = SAMPLES[m.VehicleState]
    with caplog.at_level(logging.WARNING, logger=log.name):
        assert decode_or_none(encode(good), m.VehicleState, "a state", log) == good
        assert caplog.records == []
        assert decode_or_none(b"\xc1", m.VehicleState, "a state on k", log) is None
    [record] = caplog.records
    assert record.name == log.name
    assert record.getMessage().startswith("ignoring a state on k: invalid VehicleState: ")


# -------------------------------------------------------------------- fuzz every decoder
DECODE_TYPES: list[object] = [*ALL, m.Command]

_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**64 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.binary(max_size=20),
)
_values = st.recursive(
    _scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=8,
)


def _only_typed_errors(data: bytes, cls: Any) -> None:
    with contextlib.suppress(MessageError):
        decode(data, cls)


@settings(max_examples=3000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.binary(max_size=200), st.sampled_from(DECODE_TYPES))
def test_fuzz_random_bytes(data: bytes, cls: object) -> None:
    _only_typed_errors(data, cls)


@settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from(ALL), st.data())
def test_fuzz_mutated_valid_payloads(cls: type[m.Message], data: st.DataObject) -> None:
    """Replace one field (maybe nested) of a valid payload with an arbitrary value."""
    d = msgspec.msgpack.decode(encode(SAMPLES[cls]))

    def containers(node: object) -> list[object]:
        out: list[object] = []
        if isinstance(node, dict | list):
            out.append(node)
            for child in node.values() if isinstance(node, dict) else node:
                out.extend(containers(child))
        return out

    target = data.draw(st.sampled_from(containers(d)))
    new_value = data.draw(_values)
    if isinstance(target, dict) and target:
        key = data.draw(st.sampled_from(sorted(target, key=str)))
        target[key] = new_value
    elif isinstance(target, list) and target:
        target[data.draw(st.integers(0, len(target) - 1))] = new_value
    _only_typed_errors(msgspec.msgpack.encode(d), data.draw(st.sampled_from([cls, m.Command])))


@settings(max_examples=2000, deadline=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from(ALL), st.data())
def test_fuzz_bit_flips(cls: type[m.Message], data: st.DataObject) -> None:
    raw = bytearray(encode(SAMPLES[cls]))
    for _ in range(data.draw(st.integers(1, 4))):
        i = data.draw(st.integers(0, len(raw) - 1))
        raw[i] ^= 1 << data.draw(st.integers(0, 7))
    cut = data.draw(st.integers(0, len(raw)))
    _only_typed_errors(bytes(raw[:cut]), cls)
