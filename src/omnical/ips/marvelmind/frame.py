"""The frame envelope: header, payload, CRC (marvelmind.md §1.2).

:func:`encode_frame` wraps a payload, :func:`parse_frame` checks and unwraps one into a
:class:`RawFrame`. Byte layout: docs/locate.md.
"""

from __future__ import annotations

from dataclasses import dataclass

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codes import (
    DESTINATION,
    FRAME_OVERHEAD,
    HEADER_LENGTH,
    MAX_PAYLOAD_LENGTH,
    PacketType,
    code_label,
)
from omnical.ips.marvelmind.crc import crc16_modbus, crc_bytes


@dataclass(frozen=True, slots=True, kw_only=True)
class RawFrame:
    """A frame whose payload omnical does not decode (unknown code, or type 0x4A).

    Attributes:
        packet_type: byte 1 of the frame (0x47 or 0x4A).
        code: the data code.
        payload: the payload bytes as received.
    """

    packet_type: int
    code: int
    payload: bytes


def encode_frame(code: int, payload: bytes, packet_type: int = PacketType.STREAM) -> bytes:
    """Wrap a payload into a complete frame: header, payload, CRC.

    Args:
        code: the data code (0…0xFFFF).
        payload: at most 255 bytes.
        packet_type: byte 1 of the frame, 0x47 for streaming data.

    Returns:
        The frame, ``len(payload) + 7`` bytes long.

    Raises:
        ProtocolError: the payload is longer than 255 bytes or a header field is out of range.
    """
    if len(payload) > MAX_PAYLOAD_LENGTH:
        msg = (
            f"data code {code_label(code)}: payload of {len(payload)} bytes exceeds "
            f"the {MAX_PAYLOAD_LENGTH}-byte frame limit"
        )
        raise ProtocolError(msg)
    if not 0 <= code <= 0xFFFF or not 0 <= packet_type <= 0xFF:
        msg = f"frame header out of range: packet type {packet_type}, data code {code}"
        raise ProtocolError(msg)
    header = bytes((DESTINATION, packet_type)) + code.to_bytes(2, "little") + bytes((len(payload),))
    body = header + payload
    return body + crc_bytes(body)


def parse_frame(data: bytes | bytearray | memoryview) -> RawFrame:
    """Split exactly one frame into packet type, data code and payload, checking the envelope.

    Args:
        data: the bytes of one whole frame, nothing before or after.

    Returns:
        The frame with its payload still undecoded.

    Raises:
        ProtocolError: the destination byte is not 0xFF, the packet type is neither 0x47 nor
            0x4A, the length byte disagrees with the number of bytes, or the CRC is wrong.
    """
    frame = bytes(data)
    if len(frame) < FRAME_OVERHEAD:
        msg = f"frame of {len(frame)} bytes is shorter than the {FRAME_OVERHEAD}-byte minimum"
        raise ProtocolError(msg)
    if frame[0] != DESTINATION:
        msg = f"frame byte 0 is 0x{frame[0]:02X}, expected destination 0x{DESTINATION:02X}"
        raise ProtocolError(msg)
    if frame[1] not in (PacketType.STREAM, PacketType.WRITE_REQUEST):
        msg = f"frame byte 1 is 0x{frame[1]:02X}, expected packet type 0x47 or 0x4A"
        raise ProtocolError(msg)
    code = int.from_bytes(frame[2:4], "little")
    length = frame[4]
    if len(frame) != length + FRAME_OVERHEAD:
        msg = (
            f"data code {code_label(code)}: header announces a {length}-byte payload "
            f"({length + FRAME_OVERHEAD}-byte frame) but the frame is {len(frame)} bytes"
        )
        raise ProtocolError(msg)
    if crc16_modbus(frame) != 0:
        received = int.from_bytes(frame[-2:], "little")
        computed = crc16_modbus(frame[:-2])
        msg = (
            f"data code {code_label(code)}: CRC mismatch, frame carries 0x{received:04X}, "
            f"computed 0x{computed:04X}"
        )
        raise ProtocolError(msg)
    return RawFrame(packet_type=frame[1], code=code, payload=frame[HEADER_LENGTH:-2])


__all__ = ["RawFrame", "encode_frame", "parse_frame"]
