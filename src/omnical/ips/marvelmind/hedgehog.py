"""The writer side: turn (simulated) hedgehog measurements into a real Marvelmind byte stream.

:func:`sample_frames` encodes each :class:`HedgehogSample` (SI units) in the device's packet
order, as a hedgehog sends them.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from omnical.errors import ProtocolError
from omnical.ips.marvelmind._checks import MILLI
from omnical.ips.marvelmind.codec import Record, encode
from omnical.ips.marvelmind.codes import DataCode
from omnical.ips.marvelmind.position import HedgePosition, PositionFlag, orientation_word
from omnical.ips.marvelmind.records import (
    DISTANCE_SLOTS,
    EMPTY_DISTANCE,
    BeaconFlag,
    BeaconPositions,
    DistanceFlag,
    DistanceItem,
    Quality,
    RawDistances,
    StationaryBeacon,
)

Vector3m = tuple[float, float, float]


@dataclass(frozen=True, slots=True, kw_only=True)
class HedgehogSample:
    """One measurement cycle of a hedgehog, in SI units.

    Attributes:
        timestamp_ms: emission time, ms: beacon time (uint32) or, for real-time packets, Unix
            time.
        position_m: (X, Y, Z) in m, or None when the fix failed and there is no earlier one
            (the packet then has flags bit 0 set and zero coordinates).
        distances_m: up to four (beacon address, distance in m) pairs; a distance of None is
            sent with the item's "not applicable" bit. Empty: no raw-distance packet.
        quality_percent: positioning quality, %; None: no quality packet.
        heading_rad: paired-hedgehog heading, or None (orientation "not applicable").
        latency_ms: time from emission to sending, ms.
        geofence_zone: 0, or the index of the geofence zone that raised an alarm (sets flags
            bit 7 and the quality packet's alarm byte).
        unavailable: the fix failed: flags bit 0 set ("coordinates unavailable, ignore X, Y,
            Z"), ``position_m`` (the last fix, held) sent as the coordinates all the same.
    """

    timestamp_ms: int
    position_m: Vector3m | None
    distances_m: tuple[tuple[int, float | None], ...] = ()
    quality_percent: int | None = None
    heading_rad: float | None = None
    latency_ms: int = 0
    geofence_zone: int = 0
    unavailable: bool = False


def _mm(value_m: float) -> int:
    return round(value_m * MILLI)


def position_record(
    sample: HedgehogSample, *, address: int, realtime: bool = False
) -> HedgePosition:
    """Build the position packet of a sample (0x0011, or 0x0081 when ``realtime``).

    Args:
        sample: the measurement.
        address: hedgehog address.
        realtime: send 0x0081 (int64 Unix-ms timestamp), as firmware 7.200+ does by default.

    Returns:
        The position record, coordinates rounded to mm.
    """
    flags = PositionFlag.TIMESTAMP_MS
    if sample.position_m is None or sample.unavailable:
        flags |= PositionFlag.COORDINATES_UNAVAILABLE
    if sample.position_m is None:
        x_mm = y_mm = z_mm = 0
    else:
        x_mm, y_mm, z_mm = (_mm(v) for v in sample.position_m)
    if sample.geofence_zone:
        flags |= PositionFlag.OUT_OF_GEOFENCE
    if sample.heading_rad is None:
        orientation = orientation_word(not_applicable=True)
    else:
        orientation = orientation_word(sample.heading_rad)
    return HedgePosition(
        code=DataCode.POSITION_MM_RT if realtime else DataCode.POSITION_MM,
        timestamp=sample.timestamp_ms,
        x_mm=x_mm,
        y_mm=y_mm,
        z_mm=z_mm,
        flags=flags,
        address=address,
        orientation=orientation,
        latency_ms=sample.latency_ms,
    )


def distances_record(
    sample: HedgehogSample, *, address: int, realtime: bool = False
) -> RawDistances | None:
    """Build the raw-distance packet of a sample (0x0004, or 0x0084 when ``realtime``).

    Args:
        sample: the measurement.
        address: hedgehog address.
        realtime: send 0x0084 (int64 Unix-ms timestamp).

    Returns:
        The record with unused slots empty (address 0), or None if the sample has no distances.

    Raises:
        ProtocolError: more than four distances, or a beacon address of 0 (the empty-slot mark).
    """
    if not sample.distances_m:
        return None
    if len(sample.distances_m) > DISTANCE_SLOTS:
        msg = (
            f"a raw-distance packet holds at most {DISTANCE_SLOTS} beacons, "
            f"got {len(sample.distances_m)} at timestamp {sample.timestamp_ms} ms"
        )
        raise ProtocolError(msg)
    items = []
    for beacon, distance_m in sample.distances_m:
        if beacon == 0:
            msg = f"beacon address 0 marks an empty slot (timestamp {sample.timestamp_ms} ms)"
            raise ProtocolError(msg)
        if distance_m is None:
            items.append(
                DistanceItem(address=beacon, distance_mm=0, flags=DistanceFlag.NOT_APPLICABLE)
            )
        else:
            items.append(DistanceItem(address=beacon, distance_mm=_mm(distance_m)))
    items.extend([EMPTY_DISTANCE] * (DISTANCE_SLOTS - len(items)))
    return RawDistances(
        code=DataCode.DISTANCES_RT if realtime else DataCode.DISTANCES,
        hedge_address=address,
        items=tuple(items),
        timestamp_ms=sample.timestamp_ms,
        latency_ms=sample.latency_ms,
    )


def quality_record(sample: HedgehogSample, *, address: int) -> Quality | None:
    """Build the quality packet (0x0007) of a sample.

    Args:
        sample: the measurement.
        address: hedgehog address.

    Returns:
        The record, or None if the sample has no quality.
    """
    if sample.quality_percent is None:
        return None
    return Quality(
        address=address,
        quality_percent=sample.quality_percent,
        geofence_zone=sample.geofence_zone,
    )


def sample_records(sample: HedgehogSample, *, address: int, realtime: bool = False) -> list[Record]:
    """Records of one cycle in the device's order: position, raw distances, quality.

    Args:
        sample: the measurement.
        address: hedgehog address.
        realtime: use the real-time codes 0x0081 / 0x0084.

    Returns:
        One to three records.
    """
    records: list[Record] = [position_record(sample, address=address, realtime=realtime)]
    distances = distances_record(sample, address=address, realtime=realtime)
    if distances is not None:
        records.append(distances)
    quality = quality_record(sample, address=address)
    if quality is not None:
        records.append(quality)
    return records


def sample_frames(sample: HedgehogSample, *, address: int, realtime: bool = False) -> list[bytes]:
    """Frames of one cycle in the device's order: position, raw distances, quality.

    Args:
        sample: the measurement.
        address: hedgehog address.
        realtime: use the real-time codes 0x0081 / 0x0084.

    Raises:
        ProtocolError: a value does not fit its wire field.
    """
    return [encode(r) for r in sample_records(sample, address=address, realtime=realtime)]


def beacons_record(
    beacons_m: Mapping[int, Vector3m], *, code: DataCode = DataCode.BEACONS_MM
) -> BeaconPositions:
    """Build the stationary-beacon packet (sent every 10 s while the map is frozen).

    Args:
        beacons_m: beacon address → (X, Y, Z) in m, sent in address order.
        code: 0x0012 (mm, default) or 0x0002 (cm).

    Returns:
        The record, coordinates rounded to the packet's unit (mm or cm), so that it equals
        what a reader decodes.
    """
    step_mm = 10 if code is DataCode.BEACONS_CM else 1

    def rounded(value_m: float) -> int:
        return round(value_m * MILLI / step_mm) * step_mm

    return BeaconPositions(
        code=code,
        beacons=tuple(
            StationaryBeacon(
                address=address,
                x_mm=rounded(x),
                y_mm=rounded(y),
                z_mm=rounded(z),
                flags=BeaconFlag.NONE,
            )
            for address, (x, y, z) in sorted(beacons_m.items())
        ),
    )


__all__ = [
    "HedgehogSample",
    "beacons_record",
    "distances_record",
    "position_record",
    "quality_record",
    "sample_frames",
    "sample_records",
]
