"""Records of stationary beacons (0x0002/0x0012), raw distances (0x0004/0x0084), quality (0x0007).

They keep the wire integers for a byte-exact round trip and give SI values as properties
(``position_m``, ``distance_m``, …).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntFlag

from omnical.ips.marvelmind._checks import MILLI, Timestamped, require_code, require_length
from omnical.ips.marvelmind.codes import DataCode

BEACON_CODES = frozenset({DataCode.BEACONS_CM, DataCode.BEACONS_MM})
DISTANCE_CODES = frozenset({DataCode.DISTANCES, DataCode.DISTANCES_RT})
DISTANCE_SLOTS = 4
"""A raw-distance packet always carries four items; address 0 marks an empty slot."""


class BeaconFlag(IntFlag):
    """Bits of the per-beacon byte of 0x0012 (reserved in 0x0002)."""

    NONE = 0
    LOCATION_NOT_APPLICABLE = 0x01


@dataclass(frozen=True, slots=True, kw_only=True)
class StationaryBeacon:
    """One stationary beacon of a 0x0002 / 0x0012 packet.

    Attributes:
        address: beacon address.
        x_mm: X in mm (a multiple of 10 in 0x0002, which carries cm).
        y_mm: Y in mm.
        z_mm: Z in mm.
        flags: the record's last byte; bit 0 = location not applicable in 0x0012.
    """

    address: int
    x_mm: int
    y_mm: int
    z_mm: int
    flags: BeaconFlag = BeaconFlag.NONE

    def __post_init__(self) -> None:
        """Coerce the flags."""
        object.__setattr__(self, "flags", BeaconFlag(self.flags))

    @property
    def position_m(self) -> tuple[float, float, float]:
        """(X, Y, Z) in m."""
        return (self.x_mm / MILLI, self.y_mm / MILLI, self.z_mm / MILLI)


@dataclass(frozen=True, slots=True, kw_only=True)
class BeaconPositions:
    """Stationary beacon positions, data codes 0x0002 (cm) and 0x0012 (mm).

    Attributes:
        code: 0x0002 or 0x0012.
        beacons: the beacons in packet order (at most 31 in 0x0002, 18 in 0x0012).
    """

    code: DataCode = DataCode.BEACONS_MM
    beacons: tuple[StationaryBeacon, ...]

    def __post_init__(self) -> None:
        """Check the code."""
        object.__setattr__(self, "code", require_code("BeaconPositions", self.code, BEACON_CODES))
        object.__setattr__(self, "beacons", tuple(self.beacons))


class DistanceFlag(IntFlag):
    """Bits of the per-item flags byte of the raw-distance packets."""

    NONE = 0
    NOT_APPLICABLE = 0x01
    """The distance is not applicable (vendor libraries ignore this bit)."""


@dataclass(frozen=True, slots=True, kw_only=True)
class DistanceItem:
    """One 6-byte item of a raw-distance packet.

    Attributes:
        address: beacon address; 0 marks an empty slot.
        distance_mm: hedgehog–beacon distance, mm (uint32).
        flags: item flags; bit 0 = distance not applicable.
    """

    address: int
    distance_mm: int
    flags: DistanceFlag = DistanceFlag.NONE

    def __post_init__(self) -> None:
        """Coerce the flags."""
        object.__setattr__(self, "flags", DistanceFlag(self.flags))

    @property
    def is_empty(self) -> bool:
        """The slot holds no beacon (address 0)."""
        return self.address == 0

    @property
    def not_applicable(self) -> bool:
        """Flags bit 0: the distance is not applicable."""
        return DistanceFlag.NOT_APPLICABLE in self.flags

    @property
    def is_valid(self) -> bool:
        """The slot holds a beacon and the distance is applicable."""
        return not self.is_empty and not self.not_applicable

    @property
    def distance_m(self) -> float:
        """Distance in m."""
        return self.distance_mm / MILLI


EMPTY_DISTANCE = DistanceItem(address=0, distance_mm=0)


@dataclass(frozen=True, slots=True, kw_only=True)
class RawDistances(Timestamped):
    """Raw hedgehog–beacon distances, data codes 0x0004 and 0x0084 (real time).

    Attributes:
        code: 0x0004 or 0x0084.
        hedge_address: address of the hedgehog.
        items: exactly four items; empty slots have address 0.
        timestamp_ms: ultrasound emission time, ms: uint32 beacon time (0x0004) or int64 Unix
            time (0x0084).
        latency_ms: time from emission to sending, ms.
        reserved: the last payload byte.
    """

    code: DataCode = DataCode.DISTANCES
    hedge_address: int
    items: tuple[DistanceItem, ...]
    timestamp_ms: int
    latency_ms: int = 0
    reserved: int = 0

    def __post_init__(self) -> None:
        """Check the code and the number of items."""
        object.__setattr__(self, "code", require_code("RawDistances", self.code, DISTANCE_CODES))
        object.__setattr__(self, "items", tuple(self.items))
        require_length("RawDistances", "items", self.items, DISTANCE_SLOTS)

    @property
    def latency_s(self) -> float:
        """Time from emission to sending, s."""
        return self.latency_ms / MILLI

    @property
    def valid_items(self) -> tuple[DistanceItem, ...]:
        """Items that hold a beacon and an applicable distance, in slot order."""
        return tuple(item for item in self.items if item.is_valid)

    @property
    def distances_m(self) -> dict[int, float]:
        """Valid distances in m, keyed by beacon address."""
        return {item.address: item.distance_m for item in self.valid_items}


@dataclass(frozen=True, slots=True, kw_only=True)
class Quality:
    """Quality and extended location packet, data code 0x0007.

    Attributes:
        address: device address.
        quality_percent: positioning quality, % (0…100 in practice; uint8 on the wire).
        geofence_zone: 0 = no geofence alarm, 1…255 = index of the zone that raised it.
        reserved: the 13 reserved bytes.
    """

    address: int
    quality_percent: int
    geofence_zone: int = 0
    reserved: bytes = bytes(13)

    def __post_init__(self) -> None:
        """Check the reserved bytes."""
        require_length("Quality", "reserved", self.reserved, 13)

    @property
    def code(self) -> DataCode:
        """Always 0x0007."""
        return DataCode.QUALITY

    @property
    def geofence_alarm(self) -> bool:
        """A geofence zone raised an alarm."""
        return self.geofence_zone != 0


__all__ = [
    "BEACON_CODES",
    "DISTANCE_CODES",
    "DISTANCE_SLOTS",
    "EMPTY_DISTANCE",
    "BeaconFlag",
    "BeaconPositions",
    "DistanceFlag",
    "DistanceItem",
    "Quality",
    "RawDistances",
    "StationaryBeacon",
]
