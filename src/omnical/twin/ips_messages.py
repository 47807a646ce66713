"""What the simulated IPS streams, one frozen record of columns per topic.

Columns follow the Marvelmind ROS messages with SI units named; every row names its measurement
(``measurement_index``) so that evaluation can join it with :class:`IpsTruth`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

__all__ = [
    "FLAG_COORDINATES_UNAVAILABLE",
    "FLAG_TIMESTAMP_MS",
    "IpsBeaconPositions",
    "IpsDistances",
    "IpsMeasurements",
    "IpsPositions",
    "IpsQuality",
    "IpsTruth",
]

FLAG_COORDINATES_UNAVAILABLE = 0x01
"""Position flags bit 0: coordinates unavailable, ignore x, y, z [IF p.15]."""
FLAG_TIMESTAMP_MS = 0x02
"""Position flags bit 1: the timestamp counts milliseconds [IF p.16]."""

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]
Bool = NDArray[np.bool_]


@dataclass(frozen=True)
class IpsPositions:
    """Position messages (``hedge_pos_ang``), one per measurement that reached the host, (P,).

    ``measurement_index`` links each row to :class:`IpsTruth`.
    """

    t_s: F64
    timestamp_ms: I64
    x_m: F64
    y_m: F64
    z_m: F64
    flags: U8
    address: U8
    angle_deg: F64
    measurement_index: I64


@dataclass(frozen=True)
class IpsDistances:
    """Raw distance messages (``beacon_raw_distance``), one per hedgehog–beacon distance, (D,).

    ``is_outlier`` (random reflection or NLOS zone) and ``true_distance_m`` are simulation
    truth for tests and evaluation; a real recording has neither.
    """

    t_s: F64
    address_hedge: U8
    address_beacon: U8
    distance_m: F64
    is_outlier: Bool
    true_distance_m: F64
    measurement_index: I64


@dataclass(frozen=True)
class IpsQuality:
    """Quality messages (``hedge_quality``), one per measurement that reached the host, (Q,)."""

    t_s: F64
    address: U8
    quality_percent: U8
    measurement_index: I64


@dataclass(frozen=True)
class IpsBeaconPositions:
    """Stationary beacon messages (``beacons_pos_a``), all beacons every repeat period, (R,)."""

    t_s: F64
    address: U8
    x_m: F64
    y_m: F64
    z_m: F64


@dataclass(frozen=True)
class IpsTruth:
    """Ground truth of every emitted measurement, including lost ones, (M,).

    Attributes:
        t_emit_s: emission time (the time of the true position), s.
        hedge_map_m: (M, 3) true hedgehog position in the map frame, m.
        rate_hz: measurement rate in force, Hz.
        submap_addresses: (M, K) beacons of the serving submap, ascending address.
        dropped: the whole measurement was lost by radio (no message).
        fix_ok: the vendor found a fix (flags bit 0 clear).
    """

    t_emit_s: F64
    hedge_map_m: F64
    rate_hz: F64
    submap_addresses: U8
    dropped: Bool
    fix_ok: Bool


@dataclass(frozen=True)
class IpsMeasurements:
    """Everything the simulated IPS streams over a trajectory, per topic, ready to record."""

    positions: IpsPositions
    distances: IpsDistances
    quality: IpsQuality
    beacons: IpsBeaconPositions
    truth: IpsTruth
