"""The Wheeltec vehicle-controller serial protocol, byte for byte: pure functions, no I/O.

The 11-byte command and 24-byte status frames, the resynchronising :class:`StatusReader` and
the firmware's :class:`CommandParser` (for the twin's device server).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final

__all__ = [
    "ACCEL_COUNTS_PER_MPS2",
    "COMMAND_LENGTH",
    "GYRO_RADPS_PER_COUNT",
    "HEADER",
    "STATUS_LENGTH",
    "TAIL",
    "CommandFrame",
    "CommandParser",
    "ReaderStats",
    "StatusFrame",
    "StatusLimits",
    "StatusReader",
    "bcc",
    "decode_command",
    "decode_status",
    "encode_command",
    "encode_status",
    "to_int16",
]

HEADER: Final = 0x7B
TAIL: Final = 0x7D
COMMAND_LENGTH: Final = 11
STATUS_LENGTH: Final = 24
ACCEL_COUNTS_PER_MPS2: Final = 1671.84
"""The node's ``ACCEl_RATIO``: ±2 g range, 32768 / 19.6 counts per m/s²."""
GYRO_RADPS_PER_COUNT: Final = 0.00026644
"""The node's ``GYROSCOPE_RATIO``: ±500 °/s range, 1 / 65.5 / 57.30 rad/s per count."""
_MILLI: Final = 1000.0
_GRAVITY: Final = 9.80665


def bcc(data: bytes | bytearray | memoryview) -> int:
    """XOR (block check character) of all bytes."""
    value = 0
    for b in data:
        value ^= b
    return value


def to_int16(value: float) -> int:
    """Round to the nearest integer and clamp to int16 (NaN → 0)."""
    if math.isnan(value):
        return 0
    return max(-32768, min(32767, round(value)))


def _be16(value: int) -> bytes:
    return (value & 0xFFFF).to_bytes(2, "big")


def _s16(hi: int, lo: int) -> int:
    v = (hi << 8) | lo
    return v - 0x10000 if v & 0x8000 else v


@dataclass(frozen=True, slots=True)
class CommandFrame:
    """A decoded command frame, wire integers (mm/s, mm/s, mrad/s) and the two flag bytes."""

    vx_mmps: int
    vy_mmps: int
    wz_mradps: int
    mode: int = 0
    reserved: int = 0

    @property
    def twist(self) -> tuple[float, float, float]:
        """(vx m/s, vy m/s, wz rad/s)."""
        return (self.vx_mmps / _MILLI, self.vy_mmps / _MILLI, self.wz_mradps / _MILLI)


def encode_command(
    vx_mps: float, vy_mps: float, wz_radps: float, *, mode: int = 0, reserved: int = 0
) -> bytes:
    """The 11-byte velocity command; values rounded to mm/s, mrad/s and clamped to int16."""
    body = bytes([HEADER, mode & 0xFF, reserved & 0xFF])
    body += _be16(to_int16(vx_mps * _MILLI))
    body += _be16(to_int16(vy_mps * _MILLI))
    body += _be16(to_int16(wz_radps * _MILLI))
    return body + bytes([bcc(body), TAIL])


def decode_command(frame: bytes | bytearray) -> CommandFrame | None:
    """The command in an 11-byte frame, or None if header, tail or XOR is wrong."""
    if len(frame) != COMMAND_LENGTH or frame[0] != HEADER or frame[10] != TAIL:
        return None
    if bcc(frame[:9]) != frame[9]:
        return None
    return CommandFrame(
        _s16(frame[3], frame[4]),
        _s16(frame[5], frame[6]),
        _s16(frame[7], frame[8]),
        mode=frame[1],
        reserved=frame[2],
    )


@dataclass(frozen=True, slots=True)
class StatusFrame:
    """A status frame with its wire integers; SI values as properties.

    Attributes:
        stop_flag: 1 = motors disabled (low battery, E-stop switch, self-check error).
        vx_mmps, vy_mmps, wz_mradps: measured body twist (encoders through the forward
            kinematics).
        accel_counts: (x, y, z) raw accelerometer counts, body frame (ACCEL_COUNTS_PER_MPS2).
        gyro_counts: (x, y, z) raw gyro counts, body frame (GYRO_RADPS_PER_COUNT).
        battery_mv: battery voltage, mV (uint16).
    """

    stop_flag: int
    vx_mmps: int
    vy_mmps: int
    wz_mradps: int
    accel_counts: tuple[int, int, int]
    gyro_counts: tuple[int, int, int]
    battery_mv: int

    @property
    def twist(self) -> tuple[float, float, float]:
        """(vx m/s, vy m/s, wz rad/s)."""
        return (self.vx_mmps / _MILLI, self.vy_mmps / _MILLI, self.wz_mradps / _MILLI)

    @property
    def accel_mps2(self) -> tuple[float, float, float]:
        """Accelerometer x, y, z in m/s²."""
        a = self.accel_counts
        return (
            a[0] / ACCEL_COUNTS_PER_MPS2,
            a[1] / ACCEL_COUNTS_PER_MPS2,
            a[2] / ACCEL_COUNTS_PER_MPS2,
        )

    @property
    def gyro_radps(self) -> tuple[float, float, float]:
        """Gyro x, y, z in rad/s."""
        g = self.gyro_counts
        return (
            g[0] * GYRO_RADPS_PER_COUNT,
            g[1] * GYRO_RADPS_PER_COUNT,
            g[2] * GYRO_RADPS_PER_COUNT,
        )

    @property
    def battery_v(self) -> float:
        """Battery voltage, V."""
        return self.battery_mv / _MILLI

    @classmethod
    def from_si(
        cls,
        twist: tuple[float, float, float],
        *,
        accel_mps2: tuple[float, float, float] = (0.0, 0.0, _GRAVITY),
        gyro_radps: tuple[float, float, float] = (0.0, 0.0, 0.0),
        battery_v: float = 12.0,
        stop_flag: int = 0,
    ) -> StatusFrame:
        """A frame from SI values, rounded and clamped as the firmware's int16 fields."""
        return cls(
            stop_flag=stop_flag,
            vx_mmps=to_int16(twist[0] * _MILLI),
            vy_mmps=to_int16(twist[1] * _MILLI),
            wz_mradps=to_int16(twist[2] * _MILLI),
            accel_counts=(
                to_int16(accel_mps2[0] * ACCEL_COUNTS_PER_MPS2),
                to_int16(accel_mps2[1] * ACCEL_COUNTS_PER_MPS2),
                to_int16(accel_mps2[2] * ACCEL_COUNTS_PER_MPS2),
            ),
            gyro_counts=(
                to_int16(gyro_radps[0] / GYRO_RADPS_PER_COUNT),
                to_int16(gyro_radps[1] / GYRO_RADPS_PER_COUNT),
                to_int16(gyro_radps[2] / GYRO_RADPS_PER_COUNT),
            ),
            battery_mv=max(0, min(0xFFFF, round(battery_v * _MILLI))),
        )


def encode_status(status: StatusFrame) -> bytes:
    """The 24-byte status frame."""
    body = bytearray([HEADER, status.stop_flag & 0xFF])
    for v in (status.vx_mmps, status.vy_mmps, status.wz_mradps):
        body += _be16(v)
    for v in (*status.accel_counts, *status.gyro_counts):
        body += _be16(v)
    body += (status.battery_mv & 0xFFFF).to_bytes(2, "big")
    return bytes(body) + bytes([bcc(body), TAIL])


def decode_status(frame: bytes | bytearray | memoryview) -> StatusFrame | None:
    """The status in a 24-byte frame, or None if header, tail or XOR is wrong (no plausibility)."""
    f = bytes(frame)
    if len(f) != STATUS_LENGTH or f[0] != HEADER or f[23] != TAIL or bcc(f[:22]) != f[22]:
        return None
    s = [_s16(f[i], f[i + 1]) for i in range(2, 20, 2)]
    return StatusFrame(
        stop_flag=f[1],
        vx_mmps=s[0],
        vy_mmps=s[1],
        wz_mradps=s[2],
        accel_counts=(s[3], s[4], s[5]),
        gyro_counts=(s[6], s[7], s[8]),
        battery_mv=(f[20] << 8) | f[21],
    )


@dataclass(frozen=True, slots=True)
class StatusLimits:
    """Plausibility of a status frame beyond its checksum.

    Attributes:
        max_speed_mps: largest plausible |vx|, |vy| (the fastest Wheeltec bases: ~3.5 m/s wheel
            targets in the firmware).
        max_yaw_rate_radps: largest plausible |wz| (and |gyro z|).
        battery_v: (min, max) plausible battery voltage (a 12 V or 24 V pack; 0 V = no reading
            is refused).
        accel_norm_g: (min, max) plausible norm of the accelerometer, in g (a base on the floor
            feels gravity); None disables the check (a board without IMU).
    """

    max_speed_mps: float = 4.0
    max_yaw_rate_radps: float = 12.0
    battery_v: tuple[float, float] = (5.0, 60.0)
    accel_norm_g: tuple[float, float] | None = (0.4, 2.5)

    def plausible(self, s: StatusFrame) -> bool:
        """True if every field is within the limits."""
        if s.stop_flag not in (0, 1):
            return False
        vmax = self.max_speed_mps * _MILLI
        wmax = self.max_yaw_rate_radps * _MILLI
        if abs(s.vx_mmps) > vmax or abs(s.vy_mmps) > vmax or abs(s.wz_mradps) > wmax:
            return False
        if abs(s.gyro_counts[2] * GYRO_RADPS_PER_COUNT) > self.max_yaw_rate_radps:
            return False
        lo, hi = self.battery_v
        if not lo <= s.battery_v <= hi:
            return False
        if self.accel_norm_g is not None:
            norm = math.sqrt(sum(a * a for a in s.accel_mps2)) / _GRAVITY
            if not self.accel_norm_g[0] <= norm <= self.accel_norm_g[1]:
                return False
        return True


@dataclass(frozen=True, slots=True)
class ReaderStats:
    """Counters of a :class:`StatusReader`.

    Attributes:
        bytes_received: bytes fed.
        frames_ok: frames accepted.
        checksum_failures: candidates (``7B`` … 24 bytes) with a wrong tail or XOR.
        implausible: candidates with a valid XOR but implausible fields.
        bytes_skipped: bytes discarded while searching for frames.
    """

    bytes_received: int = 0
    frames_ok: int = 0
    checksum_failures: int = 0
    implausible: int = 0
    bytes_skipped: int = 0


class StatusReader:
    """Incremental, never-raising reader of a controller → host status stream.

    Args:
        limits: plausibility checks (default :class:`StatusLimits`); None accepts every frame
            with a valid tail and XOR (the vendor node's behaviour, for comparison only).
    """

    def __init__(self, limits: StatusLimits | None = StatusLimits()) -> None:
        self._limits = limits
        self._buf = bytearray()
        self._received = 0
        self._ok = 0
        self._bad_sum = 0
        self._implausible = 0
        self._skipped = 0
        self.frame_ends: list[int] = []
        """Where in the stream each frame of the last :meth:`feed` ended (bytes fed before)."""

    @property
    def stats(self) -> ReaderStats:
        """A snapshot of the counters."""
        return ReaderStats(
            self._received, self._ok, self._bad_sum, self._implausible, self._skipped
        )

    def feed(self, data: bytes | bytearray | memoryview) -> list[StatusFrame]:
        """Add bytes; return the frames they complete, in stream order."""
        buf = self._buf
        buf += data
        self._received += len(data)
        out: list[StatusFrame] = []
        ends: list[int] = []
        base = self._received - len(buf)  # the stream offset of buf[0]
        pos = 0
        end = len(buf)
        while True:
            start = buf.find(HEADER, pos)
            if start < 0:
                self._skipped += end - pos
                pos = end
                break
            self._skipped += start - pos
            pos = start
            if end - pos < STATUS_LENGTH:
                break
            frame = decode_status(buf[pos : pos + STATUS_LENGTH])
            if frame is None:
                self._bad_sum += 1
            elif self._limits is not None and not self._limits.plausible(frame):
                self._implausible += 1
            else:
                self._ok += 1
                out.append(frame)
                pos += STATUS_LENGTH
                ends.append(base + pos)
                continue
            self._skipped += 1
            pos += 1
        del buf[:pos]
        self.frame_ends = ends
        return out


class CommandParser:
    """The firmware's byte-wise command parser (what the STM32 accepts).

    Starts collecting on a ``7B``, takes exactly 11 bytes, accepts if byte 10 is ``7D`` and
    byte 9 the XOR of bytes 0–8; otherwise drops them all and waits for the next ``7B`` (no
    back-tracking, as the firmware). Frames with a mode byte other than 0 (auto-recharge,
    RGB, …) are counted and not returned.
    """

    def __init__(self) -> None:
        self._frame = bytearray()
        self.accepted = 0
        self.rejected = 0
        self.other_modes = 0

    def feed(self, data: bytes | bytearray) -> list[CommandFrame]:
        """Add bytes; return the velocity commands they complete."""
        out: list[CommandFrame] = []
        frame = self._frame
        for b in data:
            if not frame and b != HEADER:
                continue
            frame.append(b)
            if len(frame) == COMMAND_LENGTH:
                cmd = decode_command(frame)
                frame.clear()
                if cmd is None:
                    self.rejected += 1
                elif cmd.mode != 0:
                    self.other_modes += 1
                else:
                    self.accepted += 1
                    out.append(cmd)
        return out
