"""Write an indexed MCAP file in bulk: whole Message records from numpy, a chunk at a time.

The records are the MCAP specification's (https://mcap.dev/spec), byte for byte, with every
index readers use; each chunk is assembled from per-channel slices of buffers the codec encoded
in one numpy pass. File layout, record order and checksums: docs/DESIGN-NOTES.md (bags)."""

from __future__ import annotations

import struct
import sys
import zlib
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import BinaryIO, Final, Literal

import numpy as np
from numpy.typing import NDArray

from omnical.bags.messages import Frame, Packed

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd

__all__ = [
    "CHUNK_SIZE",
    "MAGIC",
    "MESSAGE_HEADER",
    "WINDOW",
    "ZSTD_LEVEL",
    "McapCompression",
    "McapWriter",
    "MessageStream",
    "message_frame",
    "zstd_compressor",
]

MAGIC: Final = b"\x89MCAP0\r\n"

CHUNK_SIZE: Final = 1 << 20
"""Uncompressed bytes of records after which a chunk is closed (what rosbags uses)."""

ZSTD_LEVEL: Final = -1
"""zstd level of compressed chunks: the first "fast" level (figures: docs/DESIGN-NOTES.md)."""

WINDOW: Final = 1 << 15
"""Messages encoded at a time (in log-time order)."""

McapCompression = Literal["zstd", ""]
"""Chunk compression: zstd, or none (an empty string, as the MCAP record says it)."""

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
_OP_CHUNK, _OP_MESSAGE_INDEX, _OP_CHUNK_INDEX = 0x06, 0x07, 0x08
_OP_STATISTICS, _OP_METADATA, _OP_METADATA_INDEX = 0x0B, 0x0C, 0x0D
_OP_SUMMARY_OFFSET, _OP_DATA_END = 0x0E, 0x0F

MESSAGE_HEADER: Final = np.dtype(
    {
        "names": ["opcode", "length", "channel_id", "sequence", "log_time", "publish_time"],
        "formats": ["u1", "<u8", "<u2", "<u4", "<u8", "<u8"],
        "offsets": [0, 1, 9, 11, 15, 23],
        "itemsize": 31,
    }
)
"""Opcode, content length and the fixed fields of a Message record (the data follows)."""

_MESSAGE_FIXED: Final = MESSAGE_HEADER.itemsize - 9  # content length = this + data size


def zstd_compressor() -> zstd.ZstdCompressor:
    """The compressor of zstd chunks: :data:`ZSTD_LEVEL`, with the frame checksum.

    Each chunk is one zstd frame with its content size and XXH64 checksum, verified by every
    zstd decoder; the Chunk record's CRC32 is then 0 ("not computed", as the spec allows).
    """
    return zstd.ZstdCompressor(
        options={
            zstd.CompressionParameter.compression_level: ZSTD_LEVEL,
            zstd.CompressionParameter.checksum_flag: 1,
        }
    )


def message_frame(channel_id: int, log_time: NDArray[np.int64], sequence_start: int) -> Frame:
    """The Message record header of each of a block of messages of one channel.

    ``publish_time`` is the log time (what the specification asks when it is not known);
    ``sequence`` counts the channel's messages from 0 (the recorder's count, modulo 2^32).
    """
    n = log_time.shape[0]
    sequence = np.arange(sequence_start, sequence_start + n, dtype=np.uint64) % (1 << 32)
    return Frame(
        MESSAGE_HEADER,
        {
            "opcode": _OP_MESSAGE,
            "channel_id": channel_id,
            "sequence": sequence.astype(np.uint32),
            "log_time": log_time,
            "publish_time": log_time,
        },
        size_field="length",
        size_bias=_MESSAGE_FIXED,
    )


@dataclass(frozen=True)
class MessageStream:
    """The messages of one channel: log times (ns, sorted) and their encoder.

    ``encode(lo, hi, frame)`` returns rows ``lo:hi`` serialised, each behind its ``frame``
    header (:func:`~omnical.bags.messages.encode_packed` does exactly that).
    """

    channel_id: int
    log_time: NDArray[np.int64]
    encode: Callable[[int, int, Frame], Packed]


def _u16(v: int) -> bytes:
    return struct.pack("<H", v)


def _u32(v: int) -> bytes:
    return struct.pack("<I", v)


def _u64(v: int) -> bytes:
    return struct.pack("<Q", v)


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return _u32(len(raw)) + raw


def _prefixed(raw: bytes) -> bytes:
    return _u32(len(raw)) + raw


def _string_map(values: Mapping[str, str]) -> bytes:
    return _prefixed(b"".join(_string(k) + _string(v) for k, v in values.items()))


def _record(opcode: int, content: bytes) -> bytes:
    return bytes((opcode,)) + _u64(len(content)) + content


@dataclass
class _ChunkIndex:
    start: int
    end: int
    offset: int
    length: int
    index_offsets: list[tuple[int, int]]
    index_length: int
    compressed_size: int
    uncompressed_size: int


@dataclass(frozen=True)
class _Block:
    """The records of a window's messages of one channel, and their Message Index entries
    (log time filled in; the offset, which depends on the chunk, when it is written)."""

    channel_id: int
    packed: Packed
    entries: NDArray[np.uint64]


@dataclass
class _Stats:
    message_count: int = 0
    start: int | None = None
    end: int | None = None
    channel_counts: dict[int, int] = field(default_factory=dict)


class McapWriter:
    """An MCAP file being written to ``stream`` (at its start): schemas and channels first,
    then :meth:`write_streams` once, metadata, and :meth:`finish`.

    Args:
        stream: A binary file open for writing, positioned at 0.
        profile: The Header's profile (``ros2`` for a ROS 2 bag).
        library: The Header's library (the writer's name and version).
        compression: ``zstd`` or ``""`` (uncompressed chunks).
        chunk_size: Close a chunk once its records reach this many bytes.
        window: Encode this many messages at a time.
    """

    def __init__(
        self,
        stream: BinaryIO,
        *,
        profile: str,
        library: str,
        compression: McapCompression,
        chunk_size: int = CHUNK_SIZE,
        window: int = WINDOW,
    ) -> None:
        if compression not in ("zstd", ""):
            msg = f"unknown MCAP chunk compression {compression!r}"
            raise ValueError(msg)
        self._out = stream
        self._pos = 0
        self._compression: McapCompression = compression
        self._zstd = zstd_compressor() if compression == "zstd" else None
        self._chunk_size = max(1, chunk_size)
        self._window = max(1, window)
        self._schemas: list[bytes] = []
        self._channels: list[bytes] = []
        self._pending: list[bytes] = []  # Schema and Channel records not yet written
        self._chunks: list[_ChunkIndex] = []
        self._metadata: list[tuple[int, int, str]] = []
        self._stats = _Stats()
        self._streamed = False
        self._write(MAGIC + _record(_OP_HEADER, _string(profile) + _string(library)))

    def _write(self, data: bytes | memoryview) -> None:
        self._out.write(data)
        self._pos += len(data)

    def add_schema(self, name: str, encoding: str, data: bytes) -> int:
        """Add a Schema record; returns its id (1, 2, ...)."""
        sid = len(self._schemas) + 1
        record = _record(
            _OP_SCHEMA, _u16(sid) + _string(name) + _string(encoding) + _prefixed(data)
        )
        self._schemas.append(record)
        self._pending.append(record)
        return sid

    def add_channel(
        self, schema_id: int, topic: str, message_encoding: str, metadata: Mapping[str, str]
    ) -> int:
        """Add a Channel record; returns its id (1, 2, ...)."""
        if not 0 <= schema_id <= len(self._schemas):
            msg = f"no schema {schema_id}"
            raise ValueError(msg)
        cid = len(self._channels) + 1
        content = (
            _u16(cid)
            + _u16(schema_id)
            + _string(topic)
            + _string(message_encoding)
            + _string_map(metadata)
        )
        record = _record(_OP_CHANNEL, content)
        self._channels.append(record)
        self._pending.append(record)
        self._stats.channel_counts[cid] = 0
        return cid

    def write_streams(self, streams: Sequence[MessageStream]) -> None:
        """Write every message of ``streams`` in chunks, in log-time order across streams
        (ties in the order of ``streams``). Call once, after every channel is added.

        Raises:
            ValueError: A stream's channel is unknown or has another stream, its times are not
                sorted or negative, or its encoder returned the wrong number of records.
        """
        if self._streamed:
            msg = "write_streams may be called once"
            raise ValueError(msg)
        self._streamed = True
        if len({s.channel_id for s in streams}) != len(streams):
            msg = "one stream per channel"
            raise ValueError(msg)
        for s in streams:
            if s.channel_id not in self._stats.channel_counts:
                msg = f"no channel {s.channel_id}"
                raise ValueError(msg)
            t = s.log_time
            if t.size and (int(t[0]) < 0 or bool(np.any(np.diff(t) < 0))):
                msg = f"channel {s.channel_id}: log times must be sorted and not negative"
                raise ValueError(msg)
        if not streams:
            return
        times = np.concatenate([s.log_time.astype(np.int64, copy=False) for s in streams])
        which = np.concatenate(
            [np.full(s.log_time.shape[0], k, dtype=np.int32) for k, s in enumerate(streams)]
        )
        order = np.argsort(times, kind="stable")
        times = times[order]
        which = which[order]
        del order
        done = [0] * len(streams)  # rows of each stream written
        for w0 in range(0, times.shape[0], self._window):
            w1 = min(times.shape[0], w0 + self._window)
            self._write_window(streams, done, times[w0:w1], which[w0:w1])

    def _write_window(
        self,
        streams: Sequence[MessageStream],
        done: list[int],
        times: NDArray[np.int64],
        which: NDArray[np.int32],
    ) -> None:
        """Encode the messages of one window and write them as chunks."""
        n = times.shape[0]
        counts = np.bincount(which, minlength=len(streams)).tolist()
        blocks: list[_Block] = []
        positions: list[NDArray[np.intp]] = []
        sizes = np.empty(n, dtype=np.int64)
        for k, count in enumerate(counts):
            if not count:
                continue
            s = streams[k]
            lo, hi = done[k], done[k] + count
            log_time = s.log_time[lo:hi]
            packed = s.encode(lo, hi, message_frame(s.channel_id, log_time, lo))
            if packed.offsets.shape != (count + 1,) or packed.data.size != packed.offsets[-1]:
                msg = f"channel {s.channel_id}: encoder returned a wrong number of records"
                raise ValueError(msg)
            entries = np.empty((count, 2), dtype="<u8")  # Message Index: log time, offset
            entries[:, 0] = log_time
            blocks.append(_Block(s.channel_id, packed, entries))
            positions.append(np.flatnonzero(which == k))
            sizes[positions[-1]] = np.diff(packed.offsets)
            done[k] = hi
            self._stats.channel_counts[s.channel_id] += count
        prefix = b"".join(self._pending)
        ends = np.cumsum(sizes)
        bounds = [0]  # the window's rows of chunk c: bounds[c]:bounds[c + 1]
        while (start := bounds[-1]) < n:
            base = int(ends[start - 1]) if start else 0
            budget = self._chunk_size - (len(prefix) if start == 0 else 0)
            stop = int(np.searchsorted(ends, base + budget, side="left")) + 1
            bounds.append(min(max(stop, start + 1), n))
        rows = [np.searchsorted(pos, bounds).tolist() for pos in positions]
        for c in range(len(bounds) - 1):
            groups = [(b, r[c], r[c + 1]) for b, r in zip(blocks, rows, strict=True)]
            start, stop = bounds[c], bounds[c + 1]
            self._write_chunk(groups, prefix, int(times[start]), int(times[stop - 1]))
            prefix = b""

    def _write_chunk(
        self,
        groups: Sequence[tuple[_Block, int, int]],
        prefix: bytes,
        start_ns: int,
        end_ns: int,
    ) -> None:
        """One Chunk record of ``prefix`` and the rows ``r0:r1`` of each group's block (none
        if empty), then its Message Index records."""
        self._pending = []
        pieces: list[bytes | memoryview] = [prefix]
        indexes: list[tuple[int, NDArray[np.uint64]]] = []
        at = len(prefix)
        n_messages = 0
        for block, r0, r1 in groups:
            if r1 <= r0:
                continue
            ends = block.packed.offsets
            a, b = int(ends[r0]), int(ends[r1])
            pieces.append(block.packed.data[a:b].data)
            entries = block.entries[r0:r1]
            entries[:, 1] = ends[r0:r1] - (a - at)
            indexes.append((block.channel_id, entries))
            at += b - a
            n_messages += r1 - r0
        raw = b"".join(pieces)
        if self._zstd is None:
            body, crc = raw, zlib.crc32(raw)
        else:  # CRC 0: "not computed"; the zstd frame's checksum guards the records instead
            body, crc = self._zstd.compress(raw, zstd.ZstdCompressor.FLUSH_FRAME), 0
        head = (
            bytes((_OP_CHUNK,))
            + _u64(8 + 8 + 8 + 4 + 4 + len(self._compression) + 8 + len(body))
            + _u64(start_ns)
            + _u64(end_ns)
            + _u64(len(raw))
            + _u32(crc)
            + _string(self._compression)
            + _u64(len(body))
        )
        chunk_offset = self._pos
        self._write(head)
        self._write(body)
        chunk_end = self._pos
        offsets: list[tuple[int, int]] = []
        records: list[bytes | memoryview] = []
        at = self._pos
        for cid, entries in indexes:
            offsets.append((cid, at))
            size = entries.nbytes
            records += (
                bytes((_OP_MESSAGE_INDEX,)) + _u64(2 + 4 + size) + _u16(cid) + _u32(size),
                entries.data.cast("B"),
            )
            at += 1 + 8 + 2 + 4 + size
        self._write(b"".join(records))
        self._chunks.append(
            _ChunkIndex(
                start_ns,
                end_ns,
                chunk_offset,
                chunk_end - chunk_offset,
                offsets,
                self._pos - chunk_end,
                len(body),
                len(raw),
            )
        )
        stats = self._stats
        stats.message_count += n_messages
        if n_messages:
            stats.start = start_ns if stats.start is None else min(stats.start, start_ns)
            stats.end = end_ns if stats.end is None else max(stats.end, end_ns)

    def add_metadata(self, name: str, values: Mapping[str, str]) -> None:
        """Write a Metadata record (after the messages)."""
        if self._pending:  # schemas and channels without messages: into the data section
            self._write(b"".join(self._pending))
            self._pending = []
        offset = self._pos
        self._write(_record(_OP_METADATA, _string(name) + _string_map(values)))
        self._metadata.append((offset, self._pos - offset, name))

    def finish(self) -> None:
        """Write Data End, the summary, the summary offsets and the footer."""
        if self._pending:
            self._write(b"".join(self._pending))
            self._pending = []
        self._write(_record(_OP_DATA_END, _u32(0)))
        summary_start = self._pos
        groups: list[tuple[int, bytes]] = [
            (_OP_SCHEMA, b"".join(self._schemas)),
            (_OP_CHANNEL, b"".join(self._channels)),
            (_OP_STATISTICS, self._statistics()),
            (_OP_CHUNK_INDEX, b"".join(self._chunk_index(c) for c in self._chunks)),
            (
                _OP_METADATA_INDEX,
                b"".join(
                    _record(_OP_METADATA_INDEX, _u64(o) + _u64(n) + _string(name))
                    for o, n, name in self._metadata
                ),
            ),
        ]
        summary: list[bytes] = []
        offsets: list[bytes] = []
        at = summary_start
        for opcode, block in groups:
            if block:
                offsets.append(
                    _record(_OP_SUMMARY_OFFSET, bytes((opcode,)) + _u64(at) + _u64(len(block)))
                )
                summary.append(block)
                at += len(block)
        offsets_start = at
        tail = b"".join(summary) + b"".join(offsets)
        footer_head = bytes((_OP_FOOTER,)) + _u64(20) + _u64(summary_start) + _u64(offsets_start)
        crc = zlib.crc32(footer_head, zlib.crc32(tail))
        self._write(tail + footer_head + _u32(crc) + MAGIC)

    def _statistics(self) -> bytes:
        stats = self._stats
        counts = b"".join(_u16(c) + _u64(n) for c, n in sorted(stats.channel_counts.items()))
        content = (
            _u64(stats.message_count)
            + _u16(len(self._schemas))
            + _u32(len(self._channels))
            + _u32(0)  # attachments
            + _u32(len(self._metadata))
            + _u32(len(self._chunks))
            + _u64(stats.start or 0)
            + _u64(stats.end or 0)
            + _prefixed(counts)
        )
        return _record(_OP_STATISTICS, content)

    def _chunk_index(self, c: _ChunkIndex) -> bytes:
        index_map = b"".join(_u16(cid) + _u64(off) for cid, off in c.index_offsets)
        content = (
            _u64(c.start)
            + _u64(c.end)
            + _u64(c.offset)
            + _u64(c.length)
            + _prefixed(index_map)
            + _u64(c.index_length)
            + _string(self._compression)
            + _u64(c.compressed_size)
            + _u64(c.uncompressed_size)
        )
        return _record(_OP_CHUNK_INDEX, content)
