"""Incremental reading of a Marvelmind byte stream: framing, resynchronisation, counters.

Feed bytes of any chunking to :class:`StreamReader` (then :meth:`StreamReader.flush`), e.g. from
:func:`open_serial`; it never raises on bad input. Checks: docs/locate.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from omnical.errors import ProtocolError, RecordingError
from omnical.ips.marvelmind.codec import Record, decode_payload
from omnical.ips.marvelmind.codes import (
    DESTINATION,
    FRAME_OVERHEAD,
    HEADER_LENGTH,
    DataCode,
    PacketType,
    length_plausible,
)
from omnical.ips.marvelmind.crc import crc16_modbus
from omnical.ips.marvelmind.frame import RawFrame

if TYPE_CHECKING:
    import serial

DEFAULT_BAUDRATE = 9600
"""The vendor libraries' default; over USB (CDC) the rate does not matter."""

_PACKET_TYPES = frozenset({int(PacketType.STREAM), int(PacketType.WRITE_REQUEST)})


@dataclass(frozen=True, slots=True)
class StreamStats:
    """Snapshot of a :class:`StreamReader`'s counters.

    The byte counters add up: ``bytes_received == bytes_framed + bytes_skipped + bytes_pending``.

    Attributes:
        bytes_received: bytes fed so far.
        bytes_framed: bytes in accepted frames (decoded or unknown).
        bytes_skipped: bytes discarded while searching for frames.
        bytes_pending: bytes held back, waiting for the rest of a frame.
        frames_ok: frames decoded into typed records.
        unknown_codes: CRC-valid frames of an unknown code or of type 0x4A.
        crc_failures: candidates whose CRC did not match.
        bad_lengths: candidates whose payload length broke their code's rule.
        truncated: candidates cut off by the end of the stream (counted by ``flush``).
    """

    bytes_received: int = 0
    bytes_framed: int = 0
    bytes_skipped: int = 0
    bytes_pending: int = 0
    frames_ok: int = 0
    unknown_codes: int = 0
    crc_failures: int = 0
    bad_lengths: int = 0
    truncated: int = 0


def _known_code(code: int) -> DataCode | None:
    try:
        return DataCode(code)
    except ValueError:
        return None


class StreamReader:
    """Incremental, never-raising parser of a Marvelmind device → host byte stream.

    Args:
        return_unknown: also return frames of unknown codes (and type 0x4A) as
            :class:`RawFrame` records; they are counted either way.
    """

    def __init__(self, *, return_unknown: bool = False) -> None:
        """Create a reader with empty buffer and zero counters."""
        self._return_unknown = return_unknown
        self._buffer = bytearray()
        self._received = 0
        self._framed = 0
        self._skipped = 0
        self._ok = 0
        self._unknown = 0
        self._crc_failures = 0
        self._bad_lengths = 0
        self._truncated = 0

    @property
    def stats(self) -> StreamStats:
        """A frozen snapshot of the counters."""
        return StreamStats(
            bytes_received=self._received,
            bytes_framed=self._framed,
            bytes_skipped=self._skipped,
            bytes_pending=len(self._buffer),
            frames_ok=self._ok,
            unknown_codes=self._unknown,
            crc_failures=self._crc_failures,
            bad_lengths=self._bad_lengths,
            truncated=self._truncated,
        )

    def feed(self, data: bytes | bytearray | memoryview) -> list[Record]:
        """Add bytes and return the records of the frames they complete.

        Args:
            data: the next bytes of the stream, any chunk size.

        Returns:
            Records in stream order (empty if no frame was completed).
        """
        self._buffer += data
        self._received += len(data)
        return self._scan(final=False)

    def flush(self) -> list[Record]:
        """Declare the end of the stream: give up on incomplete candidates, scan the rest.

        After this, no bytes are pending and the reader can be fed a new stream.

        Returns:
            Records of the frames found after abandoning the incomplete candidates.
        """
        return self._scan(final=True)

    def _skip(self, n: int) -> int:
        self._skipped += n
        return n

    def _scan(self, *, final: bool) -> list[Record]:
        buf = self._buffer
        out: list[Record] = []
        pos = 0
        end = len(buf)
        while pos < end:
            start = buf.find(DESTINATION, pos)
            if start < 0:
                pos += self._skip(end - pos)
                break
            pos += self._skip(start - pos)
            if end - pos >= 2 and buf[pos + 1] not in _PACKET_TYPES:
                pos += self._skip(1)
                continue
            if end - pos < HEADER_LENGTH:
                if not final:
                    break
                if end - pos >= 2:
                    self._truncated += 1
                pos += self._skip(1)
                continue
            packet_type = buf[pos + 1]
            code = buf[pos + 2] | (buf[pos + 3] << 8)
            length = buf[pos + 4]
            known = _known_code(code) if packet_type == PacketType.STREAM else None
            if known is not None and not length_plausible(known, length):
                self._bad_lengths += 1
                pos += self._skip(1)
                continue
            total = length + FRAME_OVERHEAD
            if end - pos < total:
                if not final:
                    break
                self._truncated += 1
                pos += self._skip(1)
                continue
            frame = bytes(buf[pos : pos + total])
            if crc16_modbus(frame) != 0:
                self._crc_failures += 1
                pos += self._skip(1)
                continue
            try:
                record = decode_payload(code, frame[HEADER_LENGTH:-2], packet_type)
            except ProtocolError:
                self._bad_lengths += 1
                pos += self._skip(1)
                continue
            self._framed += total
            pos += total
            if isinstance(record, RawFrame):
                self._unknown += 1
                if self._return_unknown:
                    out.append(record)
            else:
                self._ok += 1
                out.append(record)
        del buf[:pos]
        return out


def open_serial(
    port: str, baudrate: int = DEFAULT_BAUDRATE, *, timeout_s: float | None = 0.1
) -> serial.Serial:
    """Open a serial port (``/dev/ttyACM0``, ``COM3``, …) to a Marvelmind device, 8N1.

    Args:
        port: the port name.
        baudrate: the UART rate (default 9600 as the vendor libraries; the device's UART
            default is 500000; over USB it does not matter).
        timeout_s: read timeout in s; None blocks until the requested bytes arrive.

    Returns:
        The open ``serial.Serial``; close it, or use it as a context manager.

    Raises:
        RecordingError: the port cannot be opened; the message names the port.
    """
    import serial  # the I/O edge: only this function needs pyserial

    try:
        return serial.Serial(port, baudrate=baudrate, timeout=timeout_s)
    except (serial.SerialException, ValueError) as err:
        msg = f"cannot open serial port {port!r} at {baudrate} baud: {err}"
        raise RecordingError(msg) from err


__all__ = [
    "DEFAULT_BAUDRATE",
    "StreamReader",
    "StreamStats",
    "open_serial",
]
