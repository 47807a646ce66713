"""Records of the sensor packets: raw IMU (0x0003/0x0083), processed IMU (0x0005/0x0085), telemetry.

As for the position records, the fields are the wire's integers (counts, mg, mm/s, reserved bytes)
and the SI values are properties (marvelmind.md §1.8–1.10 give the scales).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntFlag

from omnical.ips.marvelmind._checks import MILLI, Timestamped, require_code, require_length
from omnical.ips.marvelmind.codes import DataCode

STANDARD_GRAVITY_MPS2 = 9.80665
GYRO_DEG_PER_S_PER_COUNT = 0.0175
COMPASS_COUNTS_PER_GAUSS_XY = 1100.0
COMPASS_COUNTS_PER_GAUSS_Z = 980.0
TESLA_PER_GAUSS = 1e-4
QUATERNION_SCALE = 10000.0

IMU_RAW_CODES = frozenset({DataCode.IMU_RAW, DataCode.IMU_RAW_RT})
IMU_FUSION_CODES = frozenset({DataCode.IMU_FUSION, DataCode.IMU_FUSION_RT})

Vector3 = tuple[int, int, int]


class ImuRawFlag(IntFlag):
    """Flags byte of the raw IMU packets."""

    NONE = 0
    ACCELEROMETER_UNAVAILABLE = 0x01
    GYROSCOPE_UNAVAILABLE = 0x02
    COMPASS_UNAVAILABLE = 0x04


@dataclass(frozen=True, slots=True, kw_only=True)
class RawImu(Timestamped):
    """Raw inertial data, data codes 0x0003 and 0x0083 (real time).

    Attributes:
        code: 0x0003 or 0x0083.
        acceleration_mg: accelerometer X, Y, Z, 1 mg per count (int16).
        gyro_counts: gyroscope X, Y, Z, 0.0175 °/s per count (int16).
        compass_counts: magnetometer X, Y, Z; 1100 counts/G for X and Y, 980 for Z (int16).
        address: beacon address.
        timestamp_ms: uint32 beacon time (0x0003) or int64 Unix time (0x0083), ms.
        flags: availability flags.
        reserved: the 5 reserved bytes after the address and the 3 at the end, in wire order.
    """

    code: DataCode = DataCode.IMU_RAW
    acceleration_mg: Vector3
    gyro_counts: Vector3
    compass_counts: Vector3
    address: int
    timestamp_ms: int
    flags: ImuRawFlag = ImuRawFlag.NONE
    reserved: bytes = bytes(8)

    def __post_init__(self) -> None:
        """Check the code and the sizes, coerce the flags."""
        object.__setattr__(self, "code", require_code("RawImu", self.code, IMU_RAW_CODES))
        object.__setattr__(self, "flags", ImuRawFlag(self.flags))
        for name in ("acceleration_mg", "gyro_counts", "compass_counts"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
            require_length("RawImu", name, getattr(self, name), 3)
        require_length("RawImu", "reserved", self.reserved, 8)

    @property
    def acceleration_mps2(self) -> tuple[float, float, float]:
        """Specific force X, Y, Z in m/s² (1 mg = 9.80665e-3 m/s²)."""
        ax, ay, az = (a * STANDARD_GRAVITY_MPS2 / MILLI for a in self.acceleration_mg)
        return (ax, ay, az)

    @property
    def angular_velocity_radps(self) -> tuple[float, float, float]:
        """Angular velocity X, Y, Z in rad/s."""
        wx, wy, wz = (math.radians(g * GYRO_DEG_PER_S_PER_COUNT) for g in self.gyro_counts)
        return (wx, wy, wz)

    @property
    def magnetic_field_t(self) -> tuple[float, float, float]:
        """Magnetic flux density X, Y, Z in T."""
        cx, cy, cz = self.compass_counts
        return (
            cx / COMPASS_COUNTS_PER_GAUSS_XY * TESLA_PER_GAUSS,
            cy / COMPASS_COUNTS_PER_GAUSS_XY * TESLA_PER_GAUSS,
            cz / COMPASS_COUNTS_PER_GAUSS_Z * TESLA_PER_GAUSS,
        )


class ImuFusionFlag(IntFlag):
    """Flags byte of the processed IMU packets."""

    NONE = 0
    LOCATION_UNAVAILABLE = 0x01
    QUATERNION_UNAVAILABLE = 0x02
    VELOCITY_UNAVAILABLE = 0x04
    ACCELERATION_UNAVAILABLE = 0x08


@dataclass(frozen=True, slots=True, kw_only=True)
class ProcessedImu(Timestamped):
    """IMU/ultrasound fusion output, data codes 0x0005 and 0x0085 (real time).

    Attributes:
        code: 0x0005 or 0x0085.
        position_mm: X, Y, Z in mm (int32).
        quaternion_wxyz_e4: orientation quaternion W, X, Y, Z scaled so that the norm is 10000.
        velocity_mm_s: velocity X, Y, Z in mm/s (int16).
        acceleration_mm_s2: acceleration X, Y, Z in mm/s² (int16).
        address: beacon address.
        timestamp_ms: uint32 beacon time (0x0005) or int64 Unix time (0x0085), ms.
        flags: availability flags.
        reserved: the reserved byte after the address and the 3 at the end, in wire order.
    """

    code: DataCode = DataCode.IMU_FUSION
    position_mm: Vector3
    quaternion_wxyz_e4: tuple[int, int, int, int]
    velocity_mm_s: Vector3
    acceleration_mm_s2: Vector3
    address: int
    timestamp_ms: int
    flags: ImuFusionFlag = ImuFusionFlag.NONE
    reserved: bytes = bytes(4)

    def __post_init__(self) -> None:
        """Check the code and the sizes, coerce the flags."""
        object.__setattr__(self, "code", require_code("ProcessedImu", self.code, IMU_FUSION_CODES))
        object.__setattr__(self, "flags", ImuFusionFlag(self.flags))
        for name in ("position_mm", "velocity_mm_s", "acceleration_mm_s2"):
            object.__setattr__(self, name, tuple(getattr(self, name)))
            require_length("ProcessedImu", name, getattr(self, name), 3)
        object.__setattr__(self, "quaternion_wxyz_e4", tuple(self.quaternion_wxyz_e4))
        require_length("ProcessedImu", "quaternion_wxyz_e4", self.quaternion_wxyz_e4, 4)
        require_length("ProcessedImu", "reserved", self.reserved, 4)

    @property
    def position_m(self) -> tuple[float, float, float]:
        """(X, Y, Z) in m."""
        x, y, z = (p / MILLI for p in self.position_mm)
        return (x, y, z)

    @property
    def quaternion_wxyz(self) -> tuple[float, float, float, float]:
        """Orientation quaternion (W, X, Y, Z), unit norm up to the wire's rounding."""
        w, x, y, z = (q / QUATERNION_SCALE for q in self.quaternion_wxyz_e4)
        return (w, x, y, z)

    @property
    def velocity_mps(self) -> tuple[float, float, float]:
        """Velocity X, Y, Z in m/s."""
        x, y, z = (v / MILLI for v in self.velocity_mm_s)
        return (x, y, z)

    @property
    def acceleration_mps2(self) -> tuple[float, float, float]:
        """Acceleration X, Y, Z in m/s²."""
        x, y, z = (a / MILLI for a in self.acceleration_mm_s2)
        return (x, y, z)


@dataclass(frozen=True, slots=True, kw_only=True)
class Telemetry:
    """Telemetry packet, data code 0x0006.

    Attributes:
        battery_mv: battery voltage, mV (uint16).
        rssi_dbm: radio signal strength, dBm (int8).
        address: beacon address.
        reserved: the 12 reserved bytes.
    """

    battery_mv: int
    rssi_dbm: int
    address: int
    reserved: bytes = bytes(12)

    def __post_init__(self) -> None:
        """Check the reserved bytes."""
        require_length("Telemetry", "reserved", self.reserved, 12)

    @property
    def code(self) -> DataCode:
        """Always 0x0006."""
        return DataCode.TELEMETRY

    @property
    def battery_v(self) -> float:
        """Battery voltage, V."""
        return self.battery_mv / MILLI


__all__ = [
    "IMU_FUSION_CODES",
    "IMU_RAW_CODES",
    "ImuFusionFlag",
    "ImuRawFlag",
    "ProcessedImu",
    "RawImu",
    "Telemetry",
]
