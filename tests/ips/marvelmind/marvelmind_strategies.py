"""Hypothesis strategies for Marvelmind records with every field inside its wire range."""

from __future__ import annotations

from hypothesis import strategies as st

from omnical.ips.marvelmind.codec import Record
from omnical.ips.marvelmind.codes import DataCode, PacketType
from omnical.ips.marvelmind.frame import RawFrame
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

U8 = st.integers(0, 0xFF)
U16 = st.integers(0, 0xFFFF)
U32 = st.integers(0, 0xFFFF_FFFF)
I8 = st.integers(-0x80, 0x7F)
I16 = st.integers(-0x8000, 0x7FFF)
I32 = st.integers(-0x8000_0000, 0x7FFF_FFFF)
I64 = st.integers(-(2**63), 2**63 - 1)
KNOWN_CODES = frozenset(int(c) for c in DataCode)


def _timestamp(realtime: bool) -> st.SearchStrategy[int]:
    return I64 if realtime else U32


def _vec3(elements: st.SearchStrategy[int]) -> st.SearchStrategy[tuple[int, int, int]]:
    return st.tuples(elements, elements, elements)


@st.composite
def positions(draw: st.DrawFn) -> HedgePosition:
    """Any valid 0x0001 / 0x0011 / 0x0081 record."""
    code = draw(
        st.sampled_from([DataCode.POSITION_CM, DataCode.POSITION_MM, DataCode.POSITION_MM_RT])
    )
    coordinate = I16.map(lambda cm: cm * 10) if code is DataCode.POSITION_CM else I32
    realtime = code is DataCode.POSITION_MM_RT
    return HedgePosition(
        code=code,
        timestamp=draw(_timestamp(realtime)),
        x_mm=draw(coordinate),
        y_mm=draw(coordinate),
        z_mm=draw(coordinate),
        flags=PositionFlag(draw(U8)),
        address=draw(U8),
        orientation=draw(U16),
        latency_ms=draw(U16),
        extension=draw(st.binary(max_size=255 - 26)) if realtime else b"",
    )


@st.composite
def beacon_positions(draw: st.DrawFn) -> BeaconPositions:
    """Any valid 0x0002 / 0x0012 record."""
    code = draw(st.sampled_from([DataCode.BEACONS_CM, DataCode.BEACONS_MM]))
    cm = code is DataCode.BEACONS_CM
    coordinate = I16.map(lambda c: c * 10) if cm else I32
    beacon = st.builds(
        StationaryBeacon,
        address=U8,
        x_mm=coordinate,
        y_mm=coordinate,
        z_mm=coordinate,
        flags=U8.map(BeaconFlag),
    )
    beacons = draw(st.lists(beacon, max_size=31 if cm else 18))
    return BeaconPositions(code=code, beacons=tuple(beacons))


@st.composite
def raw_distances(draw: st.DrawFn) -> RawDistances:
    """Any valid 0x0004 / 0x0084 record."""
    code = draw(st.sampled_from([DataCode.DISTANCES, DataCode.DISTANCES_RT]))
    item = st.builds(DistanceItem, address=U8, distance_mm=U32, flags=U8.map(DistanceFlag))
    return RawDistances(
        code=code,
        hedge_address=draw(U8),
        items=tuple(draw(st.lists(item, min_size=4, max_size=4))),
        timestamp_ms=draw(_timestamp(code is DataCode.DISTANCES_RT)),
        latency_ms=draw(U16),
        reserved=draw(U8),
    )


@st.composite
def raw_imus(draw: st.DrawFn) -> RawImu:
    """Any valid 0x0003 / 0x0083 record."""
    code = draw(st.sampled_from([DataCode.IMU_RAW, DataCode.IMU_RAW_RT]))
    return RawImu(
        code=code,
        acceleration_mg=draw(_vec3(I16)),
        gyro_counts=draw(_vec3(I16)),
        compass_counts=draw(_vec3(I16)),
        address=draw(U8),
        timestamp_ms=draw(_timestamp(code is DataCode.IMU_RAW_RT)),
        flags=ImuRawFlag(draw(U8)),
        reserved=draw(st.binary(min_size=8, max_size=8)),
    )


@st.composite
def processed_imus(draw: st.DrawFn) -> ProcessedImu:
    """Any valid 0x0005 / 0x0085 record."""
    code = draw(st.sampled_from([DataCode.IMU_FUSION, DataCode.IMU_FUSION_RT]))
    return ProcessedImu(
        code=code,
        position_mm=draw(_vec3(I32)),
        quaternion_wxyz_e4=draw(st.tuples(I16, I16, I16, I16)),
        velocity_mm_s=draw(_vec3(I16)),
        acceleration_mm_s2=draw(_vec3(I16)),
        address=draw(U8),
        timestamp_ms=draw(_timestamp(code is DataCode.IMU_FUSION_RT)),
        flags=ImuFusionFlag(draw(U8)),
        reserved=draw(st.binary(min_size=4, max_size=4)),
    )


telemetries = st.builds(
    Telemetry,
    battery_mv=U16,
    rssi_dbm=I8,
    address=U8,
    reserved=st.binary(min_size=12, max_size=12),
)

qualities = st.builds(
    Quality,
    address=U8,
    quality_percent=U8,
    geofence_zone=U8,
    reserved=st.binary(min_size=13, max_size=13),
)

raw_frames = st.one_of(
    st.builds(
        RawFrame,
        packet_type=st.just(int(PacketType.STREAM)),
        code=U16.filter(lambda c: c not in KNOWN_CODES),
        payload=st.binary(max_size=255),
    ),
    st.builds(
        RawFrame,
        packet_type=st.just(int(PacketType.WRITE_REQUEST)),
        code=U16,
        payload=st.binary(max_size=255),
    ),
)

TYPED_RECORDS: dict[str, st.SearchStrategy[Record]] = {
    "position": positions(),
    "beacons": beacon_positions(),
    "distances": raw_distances(),
    "imu_raw": raw_imus(),
    "imu_fusion": processed_imus(),
    "telemetry": telemetries,
    "quality": qualities,
    "raw_frame": raw_frames,
}

records: st.SearchStrategy[Record] = st.one_of(*TYPED_RECORDS.values())
