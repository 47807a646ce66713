"""The hedgehog position record: data codes 0x0001 (cm), 0x0011 (mm), 0x0081 (mm, real time).

It keeps the wire integers (``x_mm``, flag bits) for a byte-exact round trip and gives SI
values as properties (``x_m``, ``timestamp_s``, ``heading_rad``, …).
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from enum import IntFlag

from omnical.errors import ProtocolError
from omnical.ips.marvelmind._checks import MILLI, require_code
from omnical.ips.marvelmind.codes import REALTIME_CODES, DataCode, code_label

_TICKS_PER_S_OLD_FIRMWARE = 64.0
_HEADING_MASK = 0x0FFF
_PAIR_CENTRE_BIT = 1 << 12
_ORIENTATION_NA_BIT = 1 << 13
_SPEED_SUBRECORD_ID = 0x01
_SPEED_SUBRECORD = struct.Struct("<Bhhh")

POSITION_CODES = frozenset({DataCode.POSITION_CM, DataCode.POSITION_MM, DataCode.POSITION_MM_RT})


class PositionFlag(IntFlag):
    """Bits of the flags byte of the position packets (marvelmind.md §1.5)."""

    COORDINATES_UNAVAILABLE = 0x01
    """Coordinates unavailable; ignore X, Y, Z."""
    TIMESTAMP_MS = 0x02
    """The uint32 timestamp is in ms (else in 1/64 s, firmware < 5.20)."""
    BUTTON_1 = 0x04
    """User button pressed."""
    UPLOAD_DATA_AVAILABLE = 0x08
    """Data available for upload to the user device."""
    DOWNLOAD_REQUESTED = 0x10
    """The device wants to download data from the user device."""
    BUTTON_2 = 0x20
    """Second user button pressed."""
    OTHER_HEDGEHOG = 0x40
    """The data concern another hedgehog, not the one sending."""
    OUT_OF_GEOFENCE = 0x80
    """Out of the geofencing zone (mm packets; reserved in the cm packet)."""


def orientation_word(
    heading_rad: float = 0.0, *, pair_centre: bool = False, not_applicable: bool = False
) -> int:
    """Build the orientation word of a position packet.

    Args:
        heading_rad: heading of a paired-hedgehog pair in the XY plane; wrapped into [0, 2π)
            and sent in decidegrees (0…3599).
        pair_centre: the coordinates are those of the pair centre (bit 12).
        not_applicable: the orientation is not applicable (bit 13).

    Returns:
        The 16-bit orientation word.
    """
    decidegrees = round(math.degrees(heading_rad % math.tau) * 10.0) % 3600
    word = decidegrees
    if pair_centre:
        word |= _PAIR_CENTRE_BIT
    if not_applicable:
        word |= _ORIENTATION_NA_BIT
    return word


@dataclass(frozen=True, slots=True, kw_only=True)
class HedgePosition:
    """Hedgehog position packet, data codes 0x0001 (cm), 0x0011 (mm), 0x0081 (mm, real time).

    Attributes:
        code: which of the three packets this is (decides the wire units and timestamp).
        timestamp: uint32 time of ultrasound emission since the beacon's wake-up, in ms when
            ``flags`` has TIMESTAMP_MS and in 1/64 s otherwise; for 0x0081 an int64 Unix time in
            ms. See :attr:`timestamp_s`.
        x_mm: X in mm (for 0x0001 a multiple of 10: the wire carries cm).
        y_mm: Y in mm.
        z_mm: Z in mm.
        flags: the flags byte.
        address: hedgehog address.
        orientation: the raw orientation word (see :attr:`heading_rad`).
        latency_ms: time from ultrasound emission to the sending of this packet, ms.
        extension: bytes after the 26-byte base payload of 0x0081 (an optional speed
            sub-record, id 0x01 then vx, vy, vz int16 mm/s); empty for the other codes.
    """

    code: DataCode = DataCode.POSITION_MM
    timestamp: int
    x_mm: int
    y_mm: int
    z_mm: int
    flags: PositionFlag = PositionFlag.TIMESTAMP_MS
    address: int
    orientation: int = 0
    latency_ms: int = 0
    extension: bytes = b""

    def __post_init__(self) -> None:
        """Check the code, coerce the flags."""
        code = require_code("HedgePosition", self.code, POSITION_CODES)
        object.__setattr__(self, "code", code)
        object.__setattr__(self, "flags", PositionFlag(self.flags))
        if self.extension and code is not DataCode.POSITION_MM_RT:
            msg = f"HedgePosition: only 0x0081 carries an extension, not {code_label(code)}"
            raise ProtocolError(msg)

    @property
    def is_realtime(self) -> bool:
        """True for 0x0081, whose timestamp is a Unix time in ms."""
        return self.code in REALTIME_CODES

    @property
    def timestamp_s(self) -> float:
        """Timestamp in s: Unix time for 0x0081, beacon time since wake-up otherwise."""
        if self.is_realtime or PositionFlag.TIMESTAMP_MS in self.flags:
            return self.timestamp / MILLI
        return self.timestamp / _TICKS_PER_S_OLD_FIRMWARE

    @property
    def x_m(self) -> float:
        """X in m."""
        return self.x_mm / MILLI

    @property
    def y_m(self) -> float:
        """Y in m."""
        return self.y_mm / MILLI

    @property
    def z_m(self) -> float:
        """Z in m."""
        return self.z_mm / MILLI

    @property
    def position_m(self) -> tuple[float, float, float]:
        """(X, Y, Z) in m."""
        return (self.x_m, self.y_m, self.z_m)

    @property
    def latency_s(self) -> float:
        """Time from ultrasound emission to sending, s."""
        return self.latency_ms / MILLI

    @property
    def heading_deg(self) -> float:
        """Pair heading in degrees: low 12 bits of the orientation word / 10."""
        return (self.orientation & _HEADING_MASK) / 10.0

    @property
    def heading_rad(self) -> float:
        """Pair heading in rad."""
        return math.radians(self.heading_deg)

    @property
    def pair_centre(self) -> bool:
        """Orientation bit 12: the coordinates are those of the pair centre."""
        return bool(self.orientation & _PAIR_CENTRE_BIT)

    @property
    def orientation_not_applicable(self) -> bool:
        """Orientation bit 13: no heading is available."""
        return bool(self.orientation & _ORIENTATION_NA_BIT)

    @property
    def velocity_mps(self) -> tuple[float, float, float] | None:
        """Velocity from the experimental 0x0081 speed sub-record, m/s, or None if absent."""
        ext = self.extension
        if len(ext) < _SPEED_SUBRECORD.size or ext[0] != _SPEED_SUBRECORD_ID:
            return None
        _, vx, vy, vz = _SPEED_SUBRECORD.unpack_from(ext)
        return (vx / MILLI, vy / MILLI, vz / MILLI)


__all__ = ["POSITION_CODES", "HedgePosition", "PositionFlag", "orientation_word"]
