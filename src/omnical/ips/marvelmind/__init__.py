"""The Marvelmind binary streaming protocol, byte for byte (``reference/marvelmind.md`` §1).

:func:`decode` / :func:`encode` convert one frame ↔ one record; :class:`StreamReader`,
:func:`read_from` and :func:`open_serial` parse streams; :func:`write_to` writes them.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from omnical._lazy import lazy_getattr

if TYPE_CHECKING:
    from omnical.ips.marvelmind.codec import (
        Record,
        decode,
        decode_payload,
        encode,
        encode_payload,
    )
    from omnical.ips.marvelmind.codes import (
        DataCode,
        PacketType,
        check_payload,
        length_plausible,
    )
    from omnical.ips.marvelmind.crc import crc16_modbus
    from omnical.ips.marvelmind.frame import (
        RawFrame,
        encode_frame,
        parse_frame,
    )
    from omnical.ips.marvelmind.hedgehog import (
        HedgehogSample,
        beacons_record,
        distances_record,
        encode_samples,
        position_record,
        quality_record,
        sample_frames,
        sample_records,
        write_to,
    )
    from omnical.ips.marvelmind.position import (
        HedgePosition,
        PositionFlag,
        orientation_word,
    )
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
    from omnical.ips.marvelmind.stream import (
        StreamReader,
        StreamStats,
        open_serial,
        read_from,
    )

_EXPORTS: dict[str, str] = {
    "BeaconFlag": "omnical.ips.marvelmind.records",
    "BeaconPositions": "omnical.ips.marvelmind.records",
    "DataCode": "omnical.ips.marvelmind.codes",
    "DistanceFlag": "omnical.ips.marvelmind.records",
    "DistanceItem": "omnical.ips.marvelmind.records",
    "HedgePosition": "omnical.ips.marvelmind.position",
    "HedgehogSample": "omnical.ips.marvelmind.hedgehog",
    "ImuFusionFlag": "omnical.ips.marvelmind.sensors",
    "ImuRawFlag": "omnical.ips.marvelmind.sensors",
    "PacketType": "omnical.ips.marvelmind.codes",
    "PositionFlag": "omnical.ips.marvelmind.position",
    "ProcessedImu": "omnical.ips.marvelmind.sensors",
    "Quality": "omnical.ips.marvelmind.records",
    "RawDistances": "omnical.ips.marvelmind.records",
    "RawFrame": "omnical.ips.marvelmind.frame",
    "RawImu": "omnical.ips.marvelmind.sensors",
    "Record": "omnical.ips.marvelmind.codec",
    "StationaryBeacon": "omnical.ips.marvelmind.records",
    "StreamReader": "omnical.ips.marvelmind.stream",
    "StreamStats": "omnical.ips.marvelmind.stream",
    "Telemetry": "omnical.ips.marvelmind.sensors",
    "beacons_record": "omnical.ips.marvelmind.hedgehog",
    "check_payload": "omnical.ips.marvelmind.codes",
    "crc16_modbus": "omnical.ips.marvelmind.crc",
    "decode": "omnical.ips.marvelmind.codec",
    "decode_payload": "omnical.ips.marvelmind.codec",
    "distances_record": "omnical.ips.marvelmind.hedgehog",
    "encode": "omnical.ips.marvelmind.codec",
    "encode_frame": "omnical.ips.marvelmind.frame",
    "encode_payload": "omnical.ips.marvelmind.codec",
    "encode_samples": "omnical.ips.marvelmind.hedgehog",
    "length_plausible": "omnical.ips.marvelmind.codes",
    "open_serial": "omnical.ips.marvelmind.stream",
    "orientation_word": "omnical.ips.marvelmind.position",
    "parse_frame": "omnical.ips.marvelmind.frame",
    "position_record": "omnical.ips.marvelmind.hedgehog",
    "quality_record": "omnical.ips.marvelmind.hedgehog",
    "read_from": "omnical.ips.marvelmind.stream",
    "sample_frames": "omnical.ips.marvelmind.hedgehog",
    "sample_records": "omnical.ips.marvelmind.hedgehog",
    "write_to": "omnical.ips.marvelmind.hedgehog",
}
"""Exported name → the module that defines it, imported on first use (PEP 562)."""

__all__ = [
    "BeaconFlag",
    "BeaconPositions",
    "DataCode",
    "DistanceFlag",
    "DistanceItem",
    "HedgePosition",
    "HedgehogSample",
    "ImuFusionFlag",
    "ImuRawFlag",
    "PacketType",
    "PositionFlag",
    "ProcessedImu",
    "Quality",
    "RawDistances",
    "RawFrame",
    "RawImu",
    "Record",
    "StationaryBeacon",
    "StreamReader",
    "StreamStats",
    "Telemetry",
    "beacons_record",
    "check_payload",
    "crc16_modbus",
    "decode",
    "decode_payload",
    "distances_record",
    "encode",
    "encode_frame",
    "encode_payload",
    "encode_samples",
    "length_plausible",
    "open_serial",
    "orientation_word",
    "parse_frame",
    "position_record",
    "quality_record",
    "read_from",
    "sample_frames",
    "sample_records",
    "write_to",
]


__getattr__ = lazy_getattr(__name__, _EXPORTS)
