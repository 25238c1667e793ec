"""The MAVLink 2 dialect the gateway speaks, chosen explicitly (never via ``MAVLINK20``).

pymavlink 2.4.50's ``common`` dialect lacks PROTOCOL_VERSION (#300), which QGroundControl asks
for during its connect sequence; it is defined here from the MAVLink XML definition (id 300,
CRC extra 217, 22-byte payload) and registered in the dialect's message map so that the
gateway can send it and pymavlink clients (our tests) can decode it.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any, ClassVar

from pymavlink.dialects.v20 import common as mavlink

__all__ = [
    "MAVLINK_MSG_ID_PROTOCOL_VERSION",
    "MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES",
    "MAV_CMD_REQUEST_PROTOCOL_VERSION",
    "Msg",
    "mavlink",
    "new_mav",
    "pack",
    "protocol_version_message",
]

MAVLINK_MSG_ID_PROTOCOL_VERSION = 300
PROTOCOL_VERSION_CURRENT = 200  # "MAVLink 2.0" as PX4 and QGC report it
MAV_CMD_REQUEST_PROTOCOL_VERSION = 519
MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES = 520

# Message ids QGroundControl asks for that we do not provide (answered UNSUPPORTED).
MAVLINK_MSG_ID_AVAILABLE_MODES = 435
MAVLINK_MSG_ID_COMPONENT_METADATA = 397
MAVLINK_MSG_ID_COMPONENT_INFORMATION = 395

# pymavlink's generated classes are untyped; they are values of this alias here.
Msg = Any


class MAVLink_protocol_version_message(mavlink.MAVLink_message):  # type: ignore[misc]
    """PROTOCOL_VERSION (#300): the MAVLink versions this system speaks.

    The class attributes mirror pymavlink's generated classes (which its parser reads).
    """

    id = MAVLINK_MSG_ID_PROTOCOL_VERSION
    msgname = "PROTOCOL_VERSION"
    fieldnames: ClassVar[list[str]] = [
        "version",
        "min_version",
        "max_version",
        "spec_version_hash",
        "library_version_hash",
    ]
    ordered_fieldnames: ClassVar[list[str]] = fieldnames
    fieldtypes: ClassVar[list[str]] = ["uint16_t", "uint16_t", "uint16_t", "uint8_t", "uint8_t"]
    fielddisplays_by_name: ClassVar[dict[str, str]] = {}
    fieldenums_by_name: ClassVar[dict[str, str]] = {}
    fieldunits_by_name: ClassVar[dict[str, str]] = {}
    native_format = bytearray(b"<HHHBB")
    orders: ClassVar[list[int]] = [0, 1, 2, 3, 4]
    lengths: ClassVar[list[int]] = [1, 1, 1, 8, 8]
    array_lengths: ClassVar[list[int]] = [0, 0, 0, 8, 8]
    crc_extra = 217
    unpacker = struct.Struct("<HHH8B8B")
    instance_field = None
    instance_offset = -1

    def __init__(
        self,
        version: int,
        min_version: int,
        max_version: int,
        spec_version_hash: Sequence[int],
        library_version_hash: Sequence[int],
    ) -> None:
        mavlink.MAVLink_message.__init__(self, self.id, self.msgname)
        self._fieldnames = self.fieldnames
        self._instance_field = self.instance_field
        self._instance_offset = self.instance_offset
        self.version = version
        self.min_version = min_version
        self.max_version = max_version
        self.spec_version_hash = list(spec_version_hash)
        self.library_version_hash = list(library_version_hash)

    def pack(self, mav: Any, force_mavlink1: bool = False) -> bytes:
        payload = self.unpacker.pack(
            self.version,
            self.min_version,
            self.max_version,
            *self.spec_version_hash[:8],
            *self.library_version_hash[:8],
        )
        packed: bytes = self._pack(mav, self.crc_extra, payload, force_mavlink1=force_mavlink1)
        return packed


mavlink.mavlink_map.setdefault(MAVLINK_MSG_ID_PROTOCOL_VERSION, MAVLink_protocol_version_message)


def protocol_version_message() -> Msg:
    return MAVLink_protocol_version_message(
        PROTOCOL_VERSION_CURRENT, 100, PROTOCOL_VERSION_CURRENT, [0] * 8, [0] * 8
    )


def new_mav(system_id: int, component_id: int) -> Any:
    """A MAVLink 2 encoder/parser object (no file: we pack and send ourselves)."""
    mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
    mav.robust_parsing = True  # bad frames come back as MAVLink_bad_data, never raise
    return mav


def pack(mav: Any, msg: Msg) -> bytes:
    """Pack ``msg`` with ``mav``'s identity, sequence and signing; advance the sequence."""
    buf: bytes = msg.pack(mav)
    mav.seq = (mav.seq + 1) % 256
    return buf
