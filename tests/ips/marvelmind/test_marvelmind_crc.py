"""CRC-16/MODBUS against the reference vectors and a bitwise oracle."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from omnical.ips.marvelmind.crc import crc16_modbus, crc_bytes


def _crc_bitwise(data: bytes) -> int:
    """Slow, obviously-correct CRC-16/MODBUS: reflected polynomial 0xA001, init 0xFFFF."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return crc


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (bytes.fromhex("ff 03 10 41 00 00"), 0xC004),
        (bytes.fromhex("ff 03 00 50 00 00"), 0x0550),
        (b"123456789", 0x4B37),
        (b"", 0xFFFF),
    ],
)
def test_reference_vectors(data: bytes, expected: int) -> None:
    assert crc16_modbus(data) == expected


def test_crc_is_sent_low_byte_first() -> None:
    assert crc_bytes(bytes.fromhex("ff 03 10 41 00 00")) == bytes.fromhex("04 c0")


@settings(max_examples=100)
@given(st.binary(max_size=300))
def test_table_matches_bitwise_oracle(data: bytes) -> None:
    assert crc16_modbus(data) == _crc_bitwise(data)


@settings(max_examples=100)
@given(st.binary(max_size=300))
def test_crc_over_message_and_crc_is_zero(data: bytes) -> None:
    assert crc16_modbus(data + crc_bytes(data)) == 0
