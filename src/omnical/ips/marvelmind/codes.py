"""Marvelmind packet types, data codes and the payload-length rule of each code.

:class:`PacketType`, :class:`DataCode`; :func:`length_plausible` and :func:`check_payload`
apply the length rules (listed in docs/locate.md).
"""

from __future__ import annotations

from enum import IntEnum
from typing import Final

from omnical.errors import ProtocolError

DESTINATION: Final = 0xFF
"""Byte 0 of every device → host frame."""

HEADER_LENGTH: Final = 5
"""Destination, packet type, data code (2 bytes), payload length."""

FRAME_OVERHEAD: Final = 7
"""Header plus the two CRC bytes: a frame is payload length + 7 bytes long."""


class PacketType(IntEnum):
    """Byte 1 of a device → host frame."""

    STREAM = 0x47
    """Streaming data (positions, distances, IMU, …)."""
    WRITE_REQUEST = 0x4A
    """The device asks to write to the user device (waypoints, zones, user payload)."""


class DataCode(IntEnum):
    """Data codes of the streaming packets (type 0x47) that omnical decodes."""

    POSITION_CM = 0x0001
    BEACONS_CM = 0x0002
    IMU_RAW = 0x0003
    DISTANCES = 0x0004
    IMU_FUSION = 0x0005
    TELEMETRY = 0x0006
    QUALITY = 0x0007
    POSITION_MM = 0x0011
    BEACONS_MM = 0x0012
    POSITION_MM_RT = 0x0081
    IMU_RAW_RT = 0x0083
    DISTANCES_RT = 0x0084
    IMU_FUSION_RT = 0x0085


CODE_NAMES: Final[dict[DataCode, str]] = {
    DataCode.POSITION_CM: "hedgehog position, cm",
    DataCode.BEACONS_CM: "stationary beacons, cm",
    DataCode.IMU_RAW: "raw IMU",
    DataCode.DISTANCES: "raw distances",
    DataCode.IMU_FUSION: "processed IMU",
    DataCode.TELEMETRY: "telemetry",
    DataCode.QUALITY: "quality",
    DataCode.POSITION_MM: "hedgehog position, mm",
    DataCode.BEACONS_MM: "stationary beacons, mm",
    DataCode.POSITION_MM_RT: "hedgehog position, mm, real-time",
    DataCode.IMU_RAW_RT: "raw IMU, real-time",
    DataCode.DISTANCES_RT: "raw distances, real-time",
    DataCode.IMU_FUSION_RT: "processed IMU, real-time",
}

REALTIME_CODES: Final = frozenset(
    {DataCode.POSITION_MM_RT, DataCode.IMU_RAW_RT, DataCode.DISTANCES_RT, DataCode.IMU_FUSION_RT}
)
"""Codes whose timestamp is an int64 Unix time in ms (firmware 7.200+)."""

FIXED_PAYLOAD_LENGTH: Final[dict[DataCode, int]] = {
    DataCode.POSITION_CM: 0x10,
    DataCode.POSITION_MM: 0x16,
    DataCode.IMU_RAW: 0x20,
    DataCode.IMU_RAW_RT: 0x24,
    DataCode.DISTANCES: 0x20,
    DataCode.DISTANCES_RT: 0x24,
    DataCode.IMU_FUSION: 0x2A,
    DataCode.IMU_FUSION_RT: 0x2E,
    DataCode.TELEMETRY: 0x10,
    DataCode.QUALITY: 0x10,
}

MIN_PAYLOAD_LENGTH: Final[dict[DataCode, int]] = {DataCode.POSITION_MM_RT: 0x1A}

BEACON_RECORD_LENGTH: Final[dict[DataCode, int]] = {
    DataCode.BEACONS_CM: 8,
    DataCode.BEACONS_MM: 14,
}

MAX_PAYLOAD_LENGTH: Final = 0xFF


def code_label(code: int) -> str:
    """Name a data code for messages, e.g. ``0x0011 (hedgehog position, mm)``.

    Args:
        code: a data code, known or not.

    Returns:
        The code in hex, with its name when omnical knows it.
    """
    try:
        return f"0x{code:04X} ({CODE_NAMES[DataCode(code)]})"
    except ValueError:
        return f"0x{code:04X}"


def length_plausible(code: DataCode, length: int) -> bool:
    """Tell whether a header's payload length can be right for a known code.

    Only the header is needed, so a stream reader can reject a candidate frame before its
    payload arrives. Stationary-beacon payloads are fully checked by :func:`check_payload`.

    Args:
        code: a known data code.
        length: payload length N from byte 4 of the header.

    Returns:
        False when no payload of that length can be valid for the code.
    """
    if code in FIXED_PAYLOAD_LENGTH:
        return length == FIXED_PAYLOAD_LENGTH[code]
    if code in MIN_PAYLOAD_LENGTH:
        return length >= MIN_PAYLOAD_LENGTH[code]
    record = BEACON_RECORD_LENGTH[code]
    return length >= 1 and (length - 1) % record == 0


def check_payload(code: DataCode, payload: bytes) -> None:
    """Check the payload length of a known data code.

    Args:
        code: a known data code.
        payload: the payload bytes (without header and CRC).

    Raises:
        ProtocolError: the length breaks the code's rule; the message names the code, the
            length found and the length expected.
    """
    length = len(payload)
    if code in FIXED_PAYLOAD_LENGTH:
        expected = FIXED_PAYLOAD_LENGTH[code]
        if length != expected:
            msg = f"data code {code_label(code)}: payload is {length} bytes, expected {expected}"
            raise ProtocolError(msg)
        return
    if code in MIN_PAYLOAD_LENGTH:
        minimum = MIN_PAYLOAD_LENGTH[code]
        if length < minimum:
            msg = (
                f"data code {code_label(code)}: payload is {length} bytes, "
                f"expected at least {minimum}"
            )
            raise ProtocolError(msg)
        return
    record = BEACON_RECORD_LENGTH[code]
    if length == 0:
        msg = f"data code {code_label(code)}: payload is 0 bytes, expected 1 + {record}·n"
        raise ProtocolError(msg)
    count = payload[0]
    expected = 1 + record * count
    if length != expected:
        msg = (
            f"data code {code_label(code)}: payload is {length} bytes, expected "
            f"1 + {record}·{count} = {expected} for the {count} beacons it announces"
        )
        raise ProtocolError(msg)


__all__ = [
    "BEACON_RECORD_LENGTH",
    "CODE_NAMES",
    "DESTINATION",
    "FIXED_PAYLOAD_LENGTH",
    "FRAME_OVERHEAD",
    "HEADER_LENGTH",
    "MAX_PAYLOAD_LENGTH",
    "MIN_PAYLOAD_LENGTH",
    "REALTIME_CODES",
    "DataCode",
    "PacketType",
    "check_payload",
    "code_label",
    "length_plausible",
]
