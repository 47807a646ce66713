"""Frame and payload codec: the reference frame, offsets from the spec, round trips, errors."""

from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from marvelmind_strategies import TYPED_RECORDS

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codec import Record, decode, decode_payload, encode
from omnical.ips.marvelmind.codes import DataCode
from omnical.ips.marvelmind.crc import crc16_modbus
from omnical.ips.marvelmind.frame import RawFrame, encode_frame, parse_frame
from omnical.ips.marvelmind.position import HedgePosition, PositionFlag, orientation_word
from omnical.ips.marvelmind.records import (
    BeaconFlag,
    BeaconPositions,
    DistanceItem,
    Quality,
    RawDistances,
    StationaryBeacon,
)
from omnical.ips.marvelmind.sensors import (
    ImuFusionFlag,
    ImuRawFlag,
    ProcessedImu,
    RawImu,
    Telemetry,
)

REFERENCE_0011 = bytes.fromhex(
    "ff 47 11 00 16 a0 86 01 00 d2 04 00 00 c9 fd ff ff 7a 03 00 00 02 05 00 20 19 00 03 10"
)


def _put(buf: bytearray, offset: int, value: int, size: int, *, signed: bool = False) -> None:
    buf[offset : offset + size] = value.to_bytes(size, "little", signed=signed)


def test_reference_0011_frame_decodes_as_stated() -> None:
    rec = decode(REFERENCE_0011)
    assert isinstance(rec, HedgePosition)
    assert rec.code is DataCode.POSITION_MM
    assert (rec.timestamp, rec.x_mm, rec.y_mm, rec.z_mm) == (100000, 1234, -567, 890)
    assert rec.flags == 0x02
    assert PositionFlag.TIMESTAMP_MS in rec.flags
    assert PositionFlag.COORDINATES_UNAVAILABLE not in rec.flags
    assert rec.address == 5
    assert rec.orientation == 0x2000
    assert rec.orientation_not_applicable
    assert not rec.pair_centre
    assert rec.latency_ms == 25
    assert int.from_bytes(REFERENCE_0011[-2:], "little") == 0x1003
    assert rec.position_m == pytest.approx((1.234, -0.567, 0.890))
    assert rec.timestamp_s == pytest.approx(100.0)
    assert encode(rec) == REFERENCE_0011


def test_position_cm_offsets_and_scale() -> None:
    payload = bytearray(16)
    _put(payload, 0, 640, 4)
    _put(payload, 4, -123, 2, signed=True)
    _put(payload, 6, 456, 2, signed=True)
    _put(payload, 8, -7, 2, signed=True)
    payload[10] = 0x01  # coordinates unavailable, timestamp in 1/64 s
    payload[11] = 9
    _put(payload, 12, 0x1000 | 1800, 2)
    _put(payload, 14, 31, 2)
    rec = decode(encode_frame(0x0001, bytes(payload)))
    assert isinstance(rec, HedgePosition)
    assert (rec.x_mm, rec.y_mm, rec.z_mm) == (-1230, 4560, -70)
    assert PositionFlag.COORDINATES_UNAVAILABLE in rec.flags
    assert PositionFlag.TIMESTAMP_MS not in rec.flags
    assert rec.timestamp_s == pytest.approx(10.0)  # 640 ticks of 1/64 s
    assert rec.address == 9
    assert rec.heading_deg == pytest.approx(180.0)
    assert rec.heading_rad == pytest.approx(math.pi)
    assert rec.pair_centre
    assert not rec.orientation_not_applicable
    assert rec.latency_ms == 31


def test_position_realtime_offsets_and_speed_extension() -> None:
    payload = bytearray(26)
    _put(payload, 0, 1_700_000_000_123, 8, signed=True)
    _put(payload, 8, 1, 4, signed=True)
    _put(payload, 12, -2, 4, signed=True)
    _put(payload, 16, 3, 4, signed=True)
    payload[20] = 0xC6
    payload[21] = 77
    _put(payload, 22, 0x2000, 2)
    _put(payload, 24, 12, 2)
    speed = bytes([0x01]) + (250).to_bytes(2, "little") + (-500).to_bytes(2, "little", signed=True)
    speed += (0).to_bytes(2, "little")
    frame = encode_frame(0x0081, bytes(payload) + speed)
    rec = decode(frame)
    assert isinstance(rec, HedgePosition)
    assert rec.is_realtime
    assert rec.timestamp == 1_700_000_000_123
    assert rec.timestamp_s == pytest.approx(1_700_000_000.123)
    assert (rec.x_mm, rec.y_mm, rec.z_mm, rec.address, rec.latency_ms) == (1, -2, 3, 77, 12)
    assert PositionFlag.TIMESTAMP_MS in rec.flags
    assert PositionFlag.BUTTON_1 in rec.flags
    assert PositionFlag.BUTTON_2 not in rec.flags
    assert PositionFlag.OTHER_HEDGEHOG in rec.flags
    assert PositionFlag.OUT_OF_GEOFENCE in rec.flags
    assert PositionFlag.UPLOAD_DATA_AVAILABLE not in rec.flags
    assert PositionFlag.DOWNLOAD_REQUESTED not in rec.flags
    assert rec.velocity_mps == pytest.approx((0.25, -0.5, 0.0))
    assert encode(rec) == frame
    plain = decode(encode_frame(0x0081, bytes(payload)))
    assert isinstance(plain, HedgePosition)
    assert plain.velocity_mps is None


def test_raw_distances_offsets_with_time_shift_at_33_for_0084() -> None:
    payload = bytearray(36)
    payload[0] = 7
    items = [(11, 1500, 0), (12, 2750, 1), (0, 0, 0), (14, 4000, 0)]
    for i, (address, distance, flags) in enumerate(items):
        base = 1 + 6 * i
        payload[base] = address
        _put(payload, base + 1, distance, 4)
        payload[base + 5] = flags
    _put(payload, 25, 1_600_000_000_000, 8, signed=True)
    _put(payload, 33, 41, 2)
    payload[35] = 0xAB
    frame = encode_frame(0x0084, bytes(payload))
    rec = decode(frame)
    assert isinstance(rec, RawDistances)
    assert rec.is_realtime
    assert rec.hedge_address == 7
    assert rec.timestamp_ms == 1_600_000_000_000
    assert rec.latency_ms == 41
    assert rec.reserved == 0xAB
    assert [(it.address, it.distance_mm) for it in rec.items] == [(a, d) for a, d, _ in items]
    assert [it.not_applicable for it in rec.items] == [False, True, False, False]
    assert [it.is_empty for it in rec.items] == [False, False, True, False]
    assert rec.distances_m == {11: 1.5, 14: 4.0}
    assert encode(rec) == frame


def test_raw_distances_0004_offsets() -> None:
    payload = bytearray(32)
    payload[0] = 3
    payload[1] = 20
    _put(payload, 2, 987, 4)
    _put(payload, 25, 123456, 4)
    _put(payload, 29, 17, 2)
    rec = decode(encode_frame(0x0004, bytes(payload)))
    assert isinstance(rec, RawDistances)
    assert (rec.timestamp_ms, rec.latency_ms) == (123456, 17)
    assert rec.items[0] == DistanceItem(address=20, distance_mm=987)
    assert rec.valid_items == (rec.items[0],)


def test_raw_imu_offsets() -> None:
    payload = bytearray(36)
    for i, value in enumerate([1000, -1000, 0, 100, -200, 300, 1100, -1100, 980]):
        _put(payload, 2 * i, value, 2, signed=True)
    payload[18] = 4
    _put(payload, 24, 5_000, 8, signed=True)
    payload[32] = 0x05
    rec = decode(encode_frame(0x0083, bytes(payload)))
    assert isinstance(rec, RawImu)
    assert rec.acceleration_mg == (1000, -1000, 0)
    assert rec.acceleration_mps2 == pytest.approx((9.80665, -9.80665, 0.0))
    assert rec.angular_velocity_radps[0] == pytest.approx(math.radians(1.75))
    assert rec.magnetic_field_t == pytest.approx((1e-4, -1e-4, 1e-4))
    assert (rec.address, rec.timestamp_ms) == (4, 5_000)
    assert ImuRawFlag.ACCELEROMETER_UNAVAILABLE in rec.flags
    assert ImuRawFlag.GYROSCOPE_UNAVAILABLE not in rec.flags
    assert ImuRawFlag.COMPASS_UNAVAILABLE in rec.flags


def test_processed_imu_offsets() -> None:
    payload = bytearray(42)
    for i, value in enumerate([1000, 2000, -3000]):
        _put(payload, 4 * i, value, 4, signed=True)
    for i, value in enumerate([10000, 0, 0, 0, 100, -200, 300, 9810, 0, -1]):
        _put(payload, 12 + 2 * i, value, 2, signed=True)
    payload[32] = 6
    _put(payload, 34, 777, 4)
    payload[38] = 0x0A
    rec = decode(encode_frame(0x0005, bytes(payload)))
    assert isinstance(rec, ProcessedImu)
    assert rec.position_m == pytest.approx((1.0, 2.0, -3.0))
    assert rec.quaternion_wxyz == pytest.approx((1.0, 0.0, 0.0, 0.0))
    assert rec.velocity_mps == pytest.approx((0.1, -0.2, 0.3))
    assert rec.acceleration_mps2 == pytest.approx((9.81, 0.0, -0.001))
    assert (rec.address, rec.timestamp_ms) == (6, 777)
    assert ImuFusionFlag.QUATERNION_UNAVAILABLE in rec.flags
    assert ImuFusionFlag.ACCELERATION_UNAVAILABLE in rec.flags
    assert ImuFusionFlag.LOCATION_UNAVAILABLE not in rec.flags
    assert ImuFusionFlag.VELOCITY_UNAVAILABLE not in rec.flags


def test_telemetry_and_quality_offsets() -> None:
    tele = decode(encode_frame(0x0006, bytes([0x10, 0x0E, 0xC4, 9]) + bytes(12)))
    assert tele == Telemetry(battery_mv=3600, rssi_dbm=-60, address=9)
    assert tele.battery_v == pytest.approx(3.6)
    quality = decode(encode_frame(0x0007, bytes([9, 87, 2]) + bytes(13)))
    assert quality == Quality(address=9, quality_percent=87, geofence_zone=2)
    assert quality.geofence_alarm


def test_beacons_mm_and_cm_offsets() -> None:
    mm = (
        bytes([2])
        + bytes([1])
        + (1000).to_bytes(4, "little")
        + (-2000).to_bytes(4, "little", signed=True)
        + (3000).to_bytes(4, "little")
        + bytes([1])
    )
    mm += bytes([2]) + bytes(12) + bytes([0])
    rec = decode(encode_frame(0x0012, mm))
    assert isinstance(rec, BeaconPositions)
    assert rec.beacons[0] == StationaryBeacon(
        address=1, x_mm=1000, y_mm=-2000, z_mm=3000, flags=BeaconFlag.LOCATION_NOT_APPLICABLE
    )
    assert BeaconFlag.LOCATION_NOT_APPLICABLE in rec.beacons[0].flags
    assert rec.beacons[0].position_m == pytest.approx((1.0, -2.0, 3.0))
    assert rec.beacons[1].address == 2
    cm = bytes([1, 5]) + (-150).to_bytes(2, "little", signed=True) + bytes(4) + bytes([0])
    rec_cm = decode(encode_frame(0x0002, cm))
    assert isinstance(rec_cm, BeaconPositions)
    assert rec_cm.beacons == (StationaryBeacon(address=5, x_mm=-1500, y_mm=0, z_mm=0),)


@pytest.mark.parametrize("kind", sorted(TYPED_RECORDS))
@settings(max_examples=40, deadline=None)
@given(data=st.data())
def test_round_trip(kind: str, data: st.DataObject) -> None:
    record: Record = data.draw(TYPED_RECORDS[kind])
    frame = encode(record)
    assert frame[0] == 0xFF
    assert frame[4] == len(frame) - 7
    assert int.from_bytes(frame[2:4], "little") == record.code
    assert crc16_modbus(frame) == 0
    decoded = decode(frame)
    assert decoded == record
    assert type(decoded) is type(record)
    assert encode(decoded) == frame


@pytest.mark.parametrize(
    ("code", "good", "bad"),
    [
        (0x0001, 16, 17),
        (0x0011, 22, 23),
        (0x0011, 22, 21),
        (0x0003, 32, 31),
        (0x0083, 36, 32),
        (0x0004, 32, 36),
        (0x0084, 36, 32),
        (0x0005, 42, 46),
        (0x0085, 46, 42),
        (0x0006, 16, 15),
        (0x0007, 16, 0),
        (0x0081, 26, 25),
    ],
)
def test_wrong_length_raises_naming_code_and_lengths(code: int, good: int, bad: int) -> None:
    decode(encode_frame(code, bytes(good)))
    with pytest.raises(ProtocolError, match=rf"0x{code:04X}.*{bad} bytes.*{good}"):
        decode(encode_frame(code, bytes(bad)))


@pytest.mark.parametrize(("code", "size"), [(0x0002, 8), (0x0012, 14)])
def test_beacon_count_must_match_length(code: int, size: int) -> None:
    decode(encode_frame(code, bytes([2]) + bytes(2 * size)))
    with pytest.raises(ProtocolError, match=rf"0x{code:04X}.*expected 1 \+ {size}·3"):
        decode(encode_frame(code, bytes([3]) + bytes(2 * size)))
    with pytest.raises(ProtocolError, match=rf"0x{code:04X}.*0 bytes"):
        decode(encode_frame(code, b""))


def test_envelope_errors() -> None:
    with pytest.raises(ProtocolError, match="CRC mismatch"):
        decode(REFERENCE_0011[:-1] + bytes([REFERENCE_0011[-1] ^ 0x01]))
    with pytest.raises(ProtocolError, match="destination"):
        decode(b"\x00" + REFERENCE_0011[1:])
    with pytest.raises(ProtocolError, match="packet type"):
        decode(b"\xff\x48" + REFERENCE_0011[2:])
    with pytest.raises(ProtocolError, match="announces a 22-byte payload"):
        decode(REFERENCE_0011 + b"\x00")
    with pytest.raises(ProtocolError, match="shorter"):
        parse_frame(b"\xff\x47\x11")


def test_unknown_code_and_write_request_are_raw_frames() -> None:
    unknown = decode(encode_frame(0x0999, b"abc"))
    assert unknown == RawFrame(packet_type=0x47, code=0x0999, payload=b"abc")
    waypoint = encode_frame(0x0201, bytes(12), packet_type=0x4A)
    rec = decode(waypoint)
    assert rec == RawFrame(packet_type=0x4A, code=0x0201, payload=bytes(12))
    assert encode(rec) == waypoint
    assert decode_payload(0x0011, bytes(22), packet_type=0x4A) == RawFrame(
        packet_type=0x4A, code=0x0011, payload=bytes(22)
    )


def test_encode_rejects_out_of_range_fields() -> None:
    big = HedgePosition(
        code=DataCode.POSITION_CM, timestamp=0, x_mm=400_000, y_mm=0, z_mm=0, address=1
    )
    with pytest.raises(ProtocolError, match=r"HedgePosition as data code 0x0001"):
        encode(big)
    with pytest.raises(ProtocolError, match="at most 18"):
        encode(
            BeaconPositions(
                beacons=tuple(
                    StationaryBeacon(address=i, x_mm=0, y_mm=0, z_mm=0) for i in range(19)
                )
            )
        )
    with pytest.raises(ProtocolError, match="exceeds"):
        encode(RawFrame(packet_type=0x47, code=0x0999, payload=bytes(256)))


def test_records_reject_wrong_structure() -> None:
    with pytest.raises(ProtocolError, match="0x0004"):
        HedgePosition(code=DataCode.DISTANCES, timestamp=0, x_mm=0, y_mm=0, z_mm=0, address=0)
    with pytest.raises(ProtocolError, match="extension"):
        HedgePosition(timestamp=0, x_mm=0, y_mm=0, z_mm=0, address=0, extension=b"\x01")
    with pytest.raises(ProtocolError, match="items must hold 4"):
        RawDistances(
            hedge_address=1, items=(DistanceItem(address=1, distance_mm=1),), timestamp_ms=0
        )
    with pytest.raises(ProtocolError, match="reserved must hold 13"):
        Quality(address=1, quality_percent=1, reserved=b"")


def test_cm_encoding_rounds_to_nearest_cm() -> None:
    rec = HedgePosition(
        code=DataCode.POSITION_CM, timestamp=0, x_mm=1234, y_mm=-1236, z_mm=5, address=1
    )
    back = decode(encode(rec))
    assert isinstance(back, HedgePosition)
    assert (back.x_mm, back.y_mm, back.z_mm) == (1230, -1240, 10)


@pytest.mark.parametrize(
    ("heading_rad", "expected"),
    [(0.0, 0), (math.pi, 1800), (-math.pi / 2, 2700), (2 * math.pi - 1e-9, 0)],
)
def test_orientation_word(heading_rad: float, expected: int) -> None:
    assert orientation_word(heading_rad) == expected
    assert orientation_word(heading_rad, pair_centre=True) == expected | 0x1000
    assert orientation_word(heading_rad, not_applicable=True) == expected | 0x2000


def test_flags_decode_all_bits() -> None:
    rec = HedgePosition(timestamp=0, x_mm=0, y_mm=0, z_mm=0, address=0, flags=PositionFlag(0xFF))
    assert rec.flags == 0xFF
    assert len(list(PositionFlag)) == 8  # every bit of the byte has its name
