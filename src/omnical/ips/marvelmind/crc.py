"""CRC-16/MODBUS, the checksum that closes every Marvelmind frame (marvelmind.md §1.3).

Over a whole frame, CRC bytes included, it gives 0. Parameters: docs/locate.md.
"""

from __future__ import annotations

_POLYNOMIAL_REFLECTED = 0xA001
_INITIAL = 0xFFFF


def _make_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = (crc >> 1) ^ _POLYNOMIAL_REFLECTED if crc & 1 else crc >> 1
        table.append(crc)
    return tuple(table)


_TABLE = _make_table()


def crc16_modbus(data: bytes | bytearray | memoryview) -> int:
    """Compute the CRC-16/MODBUS of a byte string.

    Args:
        data: the bytes to check (for a Marvelmind frame: header and payload).

    Returns:
        The CRC as an integer in 0…0xFFFF; on the wire it goes low byte first.
    """
    crc = _INITIAL
    table = _TABLE
    for byte in bytes(data):
        crc = (crc >> 8) ^ table[(crc ^ byte) & 0xFF]
    return crc


def crc_bytes(data: bytes | bytearray | memoryview) -> bytes:
    """Return the two CRC bytes to append to ``data``, low byte first.

    Args:
        data: header and payload of a frame.
    """
    return crc16_modbus(data).to_bytes(2, "little")


__all__ = ["crc16_modbus", "crc_bytes"]
