"""Encode and decode the payloads of the Marvelmind streaming packets, byte for byte.

Use :func:`decode` / :func:`encode` on whole frames, :func:`decode_payload` /
:func:`encode_payload` on payloads; strict, errors as :class:`~omnical.errors.ProtocolError`.
"""

from __future__ import annotations

import struct

from omnical.errors import ProtocolError
from omnical.ips.marvelmind.codes import (
    BEACON_RECORD_LENGTH,
    MAX_PAYLOAD_LENGTH,
    DataCode,
    PacketType,
    check_payload,
    code_label,
)
from omnical.ips.marvelmind.frame import RawFrame, encode_frame, parse_frame
from omnical.ips.marvelmind.position import HedgePosition, PositionFlag
from omnical.ips.marvelmind.records import (
    BeaconFlag,
    BeaconPositions,
    DistanceFlag,
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

Record = (
    HedgePosition
    | BeaconPositions
    | RawDistances
    | RawImu
    | ProcessedImu
    | Telemetry
    | Quality
    | RawFrame
)
"""Anything :func:`decode` returns."""

_MM_PER_CM = 10

_POSITION = {
    DataCode.POSITION_CM: struct.Struct("<IhhhBBHH"),
    DataCode.POSITION_MM: struct.Struct("<IiiiBBHH"),
    DataCode.POSITION_MM_RT: struct.Struct("<qiiiBBHH"),
}
_BEACON = {
    DataCode.BEACONS_CM: struct.Struct("<BhhhB"),
    DataCode.BEACONS_MM: struct.Struct("<BiiiB"),
}
_DISTANCES = {
    DataCode.DISTANCES: struct.Struct("<B" + "BIB" * 4 + "IHB"),
    DataCode.DISTANCES_RT: struct.Struct("<B" + "BIB" * 4 + "qHB"),
}
_IMU_RAW = {
    DataCode.IMU_RAW: struct.Struct("<9hB5sIB3s"),
    DataCode.IMU_RAW_RT: struct.Struct("<9hB5sqB3s"),
}
_IMU_FUSION = {
    DataCode.IMU_FUSION: struct.Struct("<3i4h3h3hBBIB3s"),
    DataCode.IMU_FUSION_RT: struct.Struct("<3i4h3h3hBBqB3s"),
}
_TELEMETRY = struct.Struct("<HbB12s")
_QUALITY = struct.Struct("<BBB13s")


def _cm_from_mm(value_mm: int) -> int:
    """Round mm to the nearest cm (halves up), as the cm packets carry."""
    return (value_mm + _MM_PER_CM // 2) // _MM_PER_CM


def _pack(record_name: str, code: int, layout: struct.Struct, *values: object) -> bytes:
    try:
        return layout.pack(*values)
    except struct.error as err:
        msg = f"cannot encode {record_name} as data code {code_label(code)}: {err}"
        raise ProtocolError(msg) from None


def _encode_position(rec: HedgePosition) -> bytes:
    xyz = (rec.x_mm, rec.y_mm, rec.z_mm)
    if rec.code is DataCode.POSITION_CM:
        xyz = (_cm_from_mm(rec.x_mm), _cm_from_mm(rec.y_mm), _cm_from_mm(rec.z_mm))
    fields = (rec.timestamp, *xyz, int(rec.flags), rec.address, rec.orientation, rec.latency_ms)
    return _pack("HedgePosition", rec.code, _POSITION[rec.code], *fields) + rec.extension


def _decode_position(code: DataCode, payload: bytes) -> HedgePosition:
    layout = _POSITION[code]
    ts, x, y, z, flags, address, orientation, latency = layout.unpack_from(payload)
    scale = _MM_PER_CM if code is DataCode.POSITION_CM else 1
    return HedgePosition(
        code=code,
        timestamp=ts,
        x_mm=x * scale,
        y_mm=y * scale,
        z_mm=z * scale,
        flags=PositionFlag(flags),
        address=address,
        orientation=orientation,
        latency_ms=latency,
        extension=payload[layout.size :],
    )


def _encode_beacons(rec: BeaconPositions) -> bytes:
    layout = _BEACON[rec.code]
    limit = (MAX_PAYLOAD_LENGTH - 1) // BEACON_RECORD_LENGTH[rec.code]
    if len(rec.beacons) > limit:
        msg = (
            f"cannot encode BeaconPositions as data code {code_label(rec.code)}: "
            f"{len(rec.beacons)} beacons, at most {limit} fit in one frame"
        )
        raise ProtocolError(msg)
    parts = [bytes((len(rec.beacons),))]
    for b in rec.beacons:
        xyz = (b.x_mm, b.y_mm, b.z_mm)
        if rec.code is DataCode.BEACONS_CM:
            xyz = (_cm_from_mm(b.x_mm), _cm_from_mm(b.y_mm), _cm_from_mm(b.z_mm))
        parts.append(_pack("StationaryBeacon", rec.code, layout, b.address, *xyz, int(b.flags)))
    return b"".join(parts)


def _decode_beacons(code: DataCode, payload: bytes) -> BeaconPositions:
    layout = _BEACON[code]
    scale = _MM_PER_CM if code is DataCode.BEACONS_CM else 1
    beacons = tuple(
        StationaryBeacon(
            address=address,
            x_mm=x * scale,
            y_mm=y * scale,
            z_mm=z * scale,
            flags=BeaconFlag(flags),
        )
        for address, x, y, z, flags in layout.iter_unpack(payload[1:])
    )
    return BeaconPositions(code=code, beacons=beacons)


def _encode_distances(rec: RawDistances) -> bytes:
    items = [v for it in rec.items for v in (it.address, it.distance_mm, int(it.flags))]
    fields = (rec.hedge_address, *items, rec.timestamp_ms, rec.latency_ms, rec.reserved)
    return _pack("RawDistances", rec.code, _DISTANCES[rec.code], *fields)


def _decode_distances(code: DataCode, payload: bytes) -> RawDistances:
    values = _DISTANCES[code].unpack(payload)
    items = tuple(
        DistanceItem(address=a, distance_mm=d, flags=DistanceFlag(f))
        for a, d, f in (values[1 + 3 * i : 4 + 3 * i] for i in range(4))
    )
    ts, latency, reserved = values[13:]
    return RawDistances(
        code=code,
        hedge_address=values[0],
        items=items,
        timestamp_ms=ts,
        latency_ms=latency,
        reserved=reserved,
    )


def _encode_imu_raw(rec: RawImu) -> bytes:
    fields = (
        *rec.acceleration_mg,
        *rec.gyro_counts,
        *rec.compass_counts,
        rec.address,
        rec.reserved[:5],
        rec.timestamp_ms,
        int(rec.flags),
        rec.reserved[5:],
    )
    return _pack("RawImu", rec.code, _IMU_RAW[rec.code], *fields)


def _decode_imu_raw(code: DataCode, payload: bytes) -> RawImu:
    v = _IMU_RAW[code].unpack(payload)
    return RawImu(
        code=code,
        acceleration_mg=(v[0], v[1], v[2]),
        gyro_counts=(v[3], v[4], v[5]),
        compass_counts=(v[6], v[7], v[8]),
        address=v[9],
        timestamp_ms=v[11],
        flags=ImuRawFlag(v[12]),
        reserved=v[10] + v[13],
    )


def _encode_imu_fusion(rec: ProcessedImu) -> bytes:
    fields = (
        *rec.position_mm,
        *rec.quaternion_wxyz_e4,
        *rec.velocity_mm_s,
        *rec.acceleration_mm_s2,
        rec.address,
        rec.reserved[0],
        rec.timestamp_ms,
        int(rec.flags),
        rec.reserved[1:],
    )
    return _pack("ProcessedImu", rec.code, _IMU_FUSION[rec.code], *fields)


def _decode_imu_fusion(code: DataCode, payload: bytes) -> ProcessedImu:
    v = _IMU_FUSION[code].unpack(payload)
    return ProcessedImu(
        code=code,
        position_mm=(v[0], v[1], v[2]),
        quaternion_wxyz_e4=(v[3], v[4], v[5], v[6]),
        velocity_mm_s=(v[7], v[8], v[9]),
        acceleration_mm_s2=(v[10], v[11], v[12]),
        address=v[13],
        timestamp_ms=v[15],
        flags=ImuFusionFlag(v[16]),
        reserved=bytes((v[14],)) + v[17],
    )


def encode_payload(record: Record) -> bytes:
    """Encode a record's payload (no header, no CRC).

    Args:
        record: any record :func:`decode` can return.

    Raises:
        ProtocolError: a field is out of its wire range (e.g. an int16 cm coordinate beyond
            ±327.67 m) or a payload would exceed 255 bytes.
    """
    match record:
        case HedgePosition():
            payload = _encode_position(record)
        case BeaconPositions():
            payload = _encode_beacons(record)
        case RawDistances():
            payload = _encode_distances(record)
        case RawImu():
            payload = _encode_imu_raw(record)
        case ProcessedImu():
            payload = _encode_imu_fusion(record)
        case Telemetry():
            fields = (record.battery_mv, record.rssi_dbm, record.address, record.reserved)
            payload = _pack("Telemetry", DataCode.TELEMETRY, _TELEMETRY, *fields)
        case Quality():
            fields = (
                record.address,
                record.quality_percent,
                record.geofence_zone,
                record.reserved,
            )
            payload = _pack("Quality", DataCode.QUALITY, _QUALITY, *fields)
        case RawFrame():
            payload = record.payload
    if len(payload) > MAX_PAYLOAD_LENGTH:
        msg = (
            f"cannot encode data code {code_label(record.code)}: payload of {len(payload)} "
            f"bytes exceeds {MAX_PAYLOAD_LENGTH}"
        )
        raise ProtocolError(msg)
    return payload


def encode(record: Record) -> bytes:
    """Encode a record into a complete frame (header 0xFF 0x47, payload, CRC).

    Args:
        record: any record :func:`decode` can return. A :class:`RawFrame` keeps its own packet
            type; the typed records are streaming packets (type 0x47).

    Raises:
        ProtocolError: as :func:`encode_payload`.
    """
    packet_type = record.packet_type if isinstance(record, RawFrame) else PacketType.STREAM
    return encode_frame(record.code, encode_payload(record), packet_type)


def decode_payload(code: int, payload: bytes, packet_type: int = PacketType.STREAM) -> Record:
    """Decode a payload, given its data code and packet type.

    Args:
        code: the data code from the frame header.
        payload: the payload bytes.
        packet_type: byte 1 of the frame; only streaming packets (0x47) of known codes are
            decoded into typed records.

    Returns:
        The typed record, or a :class:`RawFrame` for an unknown code or a type-0x4A packet.

    Raises:
        ProtocolError: the payload length breaks the rule of a known code.
    """
    payload = bytes(payload)
    try:
        known = DataCode(code)
    except ValueError:
        known = None
    if known is None or packet_type != PacketType.STREAM:
        return RawFrame(packet_type=packet_type, code=code, payload=payload)
    check_payload(known, payload)
    if known in _POSITION:
        return _decode_position(known, payload)
    if known in _BEACON:
        return _decode_beacons(known, payload)
    if known in _DISTANCES:
        return _decode_distances(known, payload)
    if known in _IMU_RAW:
        return _decode_imu_raw(known, payload)
    if known in _IMU_FUSION:
        return _decode_imu_fusion(known, payload)
    if known is DataCode.TELEMETRY:
        battery, rssi, address, reserved = _TELEMETRY.unpack(payload)
        return Telemetry(battery_mv=battery, rssi_dbm=rssi, address=address, reserved=reserved)
    address, quality, zone, reserved = _QUALITY.unpack(payload)
    return Quality(address=address, quality_percent=quality, geofence_zone=zone, reserved=reserved)


def decode(frame: bytes | bytearray | memoryview) -> Record:
    """Decode exactly one complete frame (strict).

    Args:
        frame: the frame bytes, from the 0xFF destination byte to the CRC.

    Returns:
        The typed record, or a :class:`RawFrame` for an unknown code or a type-0x4A packet.

    Raises:
        ProtocolError: bad destination or packet type, length byte inconsistent with the frame,
            CRC mismatch, or a payload length that breaks its code's rule (the message names the
            code and the lengths).
    """
    raw = parse_frame(frame)
    return decode_payload(raw.code, raw.payload, raw.packet_type)


__all__ = ["Record", "decode", "decode_payload", "encode", "encode_payload"]
