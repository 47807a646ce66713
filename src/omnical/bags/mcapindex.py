"""Indexed reading of an MCAP file: its summary, and the messages of chosen channels.

:func:`read_summary` answers which topics, how many messages and when from the summary at the
file's end; :func:`channel_messages` inflates only the chunks holding a wanted channel and cuts
its messages out at their indexed offsets. A file without a summary or indexes gives None."""

from __future__ import annotations

import heapq
import os
import struct
import sys
from collections.abc import Collection, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag2 import ReaderError as Ros2ReaderError
from rosbags.rosbag2.storage_mcap import decompress

if sys.version_info >= (3, 14):
    from compression.zstd import ZstdError
else:
    from backports.zstd import ZstdError

__all__ = [
    "MCAP_MAGIC",
    "McapChannel",
    "McapChunk",
    "McapIndexError",
    "McapSummary",
    "channel_messages",
    "mcap_records",
    "mcap_string",
    "read_summary",
]

MCAP_MAGIC: Final = b"\x89MCAP0\r\n"
"""The 8 bytes an MCAP file starts and ends with."""
_MAGIC: Final = MCAP_MAGIC
_FOOTER_SIZE: Final = 1 + 8 + 20  # opcode, length, summary start, summary offset start, crc
_OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE = 0x02, 0x03, 0x04, 0x05
_OP_MESSAGE_INDEX, _OP_CHUNK_INDEX, _OP_STATISTICS = 0x07, 0x08, 0x0B
_MESSAGE_HEADER: Final = 1 + 8 + 2 + 4 + 8 + 8  # opcode, length, channel, sequence, 2 times
_INFLATE_ERRORS: Final[tuple[type[Exception], ...]] = (
    Ros2ReaderError,  # rosbags' decompress: unknown compression, size or CRC mismatch
    ZstdError,
    RuntimeError,  # lz4.frame
    ValueError,
)
"""What inflating a chunk's corrupt bytes raises."""


class McapIndexError(ValueError):
    """The summary, an index or a chunk of an MCAP file is malformed or truncated."""


@dataclass(frozen=True)
class McapChannel:
    """One channel: id, topic, message type (schema name), message count."""

    id: int
    topic: str
    msgtype: str
    count: int


@dataclass(frozen=True)
class McapChunk:
    """The chunk index of one chunk (offsets are from the start of the file)."""

    start_ns: int
    end_ns: int
    offset: int
    length: int
    index_offsets: dict[int, int]
    index_length: int
    compression: str
    compressed_size: int
    uncompressed_size: int


@dataclass(frozen=True)
class McapSummary:
    """What the summary section of an MCAP file says."""

    path: Path
    channels: dict[int, McapChannel]
    chunks: tuple[McapChunk, ...]
    message_count: int
    start_ns: int
    end_ns: int
    _times: dict[int, tuple[int, int]] = field(default_factory=dict, repr=False)


def mcap_string(data: bytes, pos: int) -> tuple[str, int]:
    """The length-prefixed UTF-8 string at ``pos``, and the position after it."""
    (n,) = struct.unpack_from("<I", data, pos)
    return data[pos + 4 : pos + 4 + n].decode("utf-8"), pos + 4 + n


def _u16_u64_map(data: bytes, pos: int) -> tuple[dict[int, int], int]:
    (n,) = struct.unpack_from("<I", data, pos)
    pairs = struct.iter_unpack("<HQ", data[pos + 4 : pos + 4 + n])
    return dict(pairs), pos + 4 + n


def mcap_records(data: bytes, pos: int, end: int) -> Iterator[tuple[int, int, int]]:
    """The records in ``data[pos:end]`` as (opcode, body start, body end), up to the first one
    that runs past ``end``."""
    while pos + 9 <= end:
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        body, stop = pos + 9, pos + 9 + length
        if stop > end:
            return
        yield op, body, stop
        pos = stop


def read_summary(path: Path) -> McapSummary | None:
    """The summary of the MCAP file ``path``, or None if it has no usable one.

    Usable means: a summary section with every chunk's index and the statistics record, as
    rosbags, the ROS 2 MCAP storage plugin and the ``mcap`` tools write.

    Raises:
        McapIndexError: Not an MCAP file, or a malformed summary.
        OSError: The file cannot be read.
    """
    with path.open("rb") as stream:
        if stream.read(len(_MAGIC)) != _MAGIC:
            msg = f"{path}: not an MCAP file"
            raise McapIndexError(msg)
        size = stream.seek(0, 2)
        if size < 2 * len(_MAGIC) + _FOOTER_SIZE:
            return None
        stream.seek(size - len(_MAGIC) - _FOOTER_SIZE)
        tail = stream.read(_FOOTER_SIZE + len(_MAGIC))
        if tail[-len(_MAGIC) :] != _MAGIC or tail[0] != _OP_FOOTER:
            return None
        summary_start, offsets_start = struct.unpack_from("<QQ", tail, 9)
        footer_start = size - len(_MAGIC) - _FOOTER_SIZE
        end = offsets_start or footer_start
        if not summary_start or not len(_MAGIC) <= summary_start <= end <= footer_start:
            return None
        stream.seek(summary_start)
        data = stream.read(end - summary_start)
    return _parse_summary(path, data, summary_start, size)


def _parse_summary(
    path: Path, data: bytes, summary_start: int, file_size: int
) -> McapSummary | None:
    """The summary in ``data`` (the file's bytes from ``summary_start``); every chunk index is
    checked to point inside the data section, before the summary."""
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, int]] = {}
    chunks: list[McapChunk] = []
    stats: tuple[int, int, int, dict[int, int]] | None = None
    read = 0  # the summary's bytes read as whole records
    try:
        for op, body, record_end in mcap_records(data, 0, len(data)):
            read = record_end
            if op == _OP_SCHEMA:
                (sid,) = struct.unpack_from("<H", data, body)
                schemas[sid], _ = mcap_string(data, body + 2)
            elif op == _OP_CHANNEL:
                cid, sid = struct.unpack_from("<HH", data, body)
                topic, _ = mcap_string(data, body + 4)
                channels[cid] = (topic, sid)
            elif op == _OP_CHUNK_INDEX:
                start, stop, offset, length = struct.unpack_from("<QQQQ", data, body)
                index_offsets, pos = _u16_u64_map(data, body + 32)
                (index_length,) = struct.unpack_from("<Q", data, pos)
                compression, pos = mcap_string(data, pos + 8)
                packed, unpacked = struct.unpack_from("<QQ", data, pos)
                _check_chunk_place(
                    path, len(chunks), (offset, length, index_length), summary_start, file_size
                )
                chunks.append(
                    McapChunk(
                        start, stop, offset, length, index_offsets, index_length, compression,
                        packed, unpacked,
                    )
                )  # fmt: skip
            elif op == _OP_STATISTICS:
                count, _, _, _, _, _, start, stop = struct.unpack_from("<QHIIIIQQ", data, body)
                counts, _ = _u16_u64_map(data, body + 42)
                stats = (count, start, stop, counts)
    except (struct.error, UnicodeDecodeError) as err:
        msg = f"{path}: malformed MCAP summary ({type(err).__name__}: {err})"
        raise McapIndexError(msg) from None
    if read + 9 <= len(data):  # a record's header left, its body running past the summary
        msg = f"record at summary offset {read} runs past the summary"
        raise McapIndexError(msg)
    if stats is None or (stats[0] and not chunks):
        return None
    count, start, stop, counts = stats
    return McapSummary(
        path=path,
        channels={
            cid: McapChannel(cid, topic, schemas.get(sid, ""), int(counts.get(cid, 0)))
            for cid, (topic, sid) in channels.items()
        },
        chunks=tuple(sorted(chunks, key=lambda c: (c.start_ns, c.offset))),
        message_count=count,
        start_ns=start,
        end_ns=stop,
    )


def _check_chunk_place(
    path: Path, k: int, place: tuple[int, int, int], data_end: int, file_size: int
) -> None:
    """Refuse chunk index ``k`` unless its chunk and message indexes (``place``: offset, length,
    index length, as read from the file) lie between the magic and ``data_end``, the summary's
    start."""
    offset, length, index_length = place
    where = f"{path}: corrupt MCAP summary: chunk index {k + 1}"
    if offset >= file_size:
        msg = f"{where} puts its chunk at offset {offset}, beyond the file's {file_size} bytes"
        raise McapIndexError(msg)
    if offset < len(_MAGIC) or offset + length + index_length > data_end:
        msg = (
            f"{where} puts its chunk ({length} bytes, then {index_length} bytes of message "
            f"indexes) at offset {offset}, outside the data section (bytes {len(_MAGIC)} to "
            f"{data_end} of {file_size})"
        )
        raise McapIndexError(msg)


def _index_entries(block: bytes, pos: int, channel: int) -> NDArray[np.uint64]:
    """The (log time, offset) pairs of one message index record, shape (N, 2)."""
    if pos < 0 or pos + 15 > len(block) or block[pos] != _OP_MESSAGE_INDEX:
        msg = f"no message index of channel {channel} where the chunk index says"
        raise McapIndexError(msg)
    cid, n = struct.unpack_from("<HI", block, pos + 9)
    if cid != channel or n % 16 or pos + 15 + n > len(block):
        msg = f"malformed message index of channel {channel}"
        raise McapIndexError(msg)
    return np.frombuffer(block, dtype="<u8", count=n // 8, offset=pos + 15).reshape(-1, 2)


def channel_times(summary: McapSummary, channel: int) -> tuple[int, int] | None:
    """Log times of the first and last message of ``channel`` (None if it has none).

    Reads the message indexes of the first and last chunks holding the channel only.

    Raises:
        McapIndexError: A message index is missing or malformed.
        OSError: The file cannot be read.
    """
    if channel in summary._times:
        return summary._times[channel]
    holding = [c for c in summary.chunks if channel in c.index_offsets]
    if not holding:
        return None
    first: int | None = None
    last: int | None = None
    with summary.path.open("rb") as stream:
        fd, size = stream.fileno(), os.fstat(stream.fileno()).st_size
        for chunk in holding:  # by start time: stop once no later chunk can start earlier
            if first is not None and chunk.start_ns > first:
                break
            times = _chunk_times(fd, size, chunk, channel)
            if times.size:
                first = int(times.min()) if first is None else min(first, int(times.min()))
        for chunk in sorted(holding, key=lambda c: c.end_ns, reverse=True):
            if last is not None and chunk.end_ns < last:
                break
            times = _chunk_times(fd, size, chunk, channel)
            if times.size:
                last = int(times.max()) if last is None else max(last, int(times.max()))
    if first is None or last is None:
        return None
    summary._times[channel] = (first, last)
    return first, last


def _chunk_times(fd: int, file_size: int, chunk: McapChunk, channel: int) -> NDArray[np.uint64]:
    base = chunk.offset + chunk.length
    block = _pread_exact(fd, file_size, base, chunk.index_length)
    return _index_entries(block, chunk.index_offsets[channel] - base, channel)[:, 0]


def channel_messages(
    summary: McapSummary, channels: Collection[int]
) -> Iterator[tuple[int, NDArray[np.uint64], list[bytes]]]:
    """The messages of ``channels``, chunk by chunk, as (channel, log times ns, payloads).

    Log times are MCAP's unsigned 64-bit ns, as stored (the reader checks them). Only chunks
    holding a wanted channel are inflated. A channel's parts come by their first log time, so
    it goes back in time only if its own messages do (overlapping chunks: docs/DESIGN-NOTES.md).

    Raises:
        McapIndexError: A chunk, its index or a message record is corrupt or truncated (a
            record reaching past the end of the file among them: no read is attempted).
        OSError: The file cannot be read.
    """
    wanted = set(channels)
    visits = [(c, sorted(wanted.intersection(c.index_offsets))) for c in summary.chunks]
    visits = [(c, here) for c, here in visits if here]
    # next_start[k][cid]: start time of the next chunk after visit k holding cid (none: end)
    next_start: list[dict[int, int]] = [{} for _ in visits]
    later: dict[int, int] = {}
    for k in range(len(visits) - 1, -1, -1):
        chunk, here = visits[k]
        next_start[k] = {cid: later[cid] for cid in here if cid in later}
        later.update(dict.fromkeys(here, chunk.start_ns))
    held: dict[int, list[tuple[int, int, NDArray[np.uint64], list[bytes]]]] = {}
    with summary.path.open("rb") as stream:
        fd = stream.fileno()
        size = os.fstat(fd).st_size
        for k, (chunk, here) in enumerate(visits):
            raw, block = _load_chunk(fd, size, chunk, _topics_of(summary, chunk))
            base = chunk.offset + chunk.length
            for cid in here:
                entries = _index_entries(block, chunk.index_offsets[cid] - base, cid)
                times, payloads = _cut(raw, entries, cid)
                parts = held.get(cid)
                bound = next_start[k].get(cid)
                first = int(times[0]) if times.size else chunk.start_ns
                if not parts and (bound is None or first < bound):  # a tie: write order
                    yield cid, times, payloads  # no overlap: at once, as read
                    continue
                parts = held.setdefault(cid, [])
                heapq.heappush(parts, (first, chunk.offset, times, payloads))
                while parts and (bound is None or parts[0][0] < bound):
                    *_, times, payloads = heapq.heappop(parts)
                    yield cid, times, payloads


def _topics_of(summary: McapSummary, chunk: McapChunk) -> str:
    """The topics of a chunk's channels, for a message (the first three)."""
    topics = sorted(
        {summary.channels[c].topic for c in chunk.index_offsets if c in summary.channels}
    )
    return ", ".join(topics[:3]) + (", ..." if len(topics) > 3 else "") or "no known topic"


def _load_chunk(fd: int, file_size: int, chunk: McapChunk, topics: str) -> tuple[bytes, bytes]:
    """A chunk, inflated, and its message index block (positioned reads).

    Raises:
        McapIndexError: The chunk is missing, truncated or corrupt (naming its offset and
            ``topics``, the topics it holds).
    """
    record = _pread_exact(fd, file_size, chunk.offset, chunk.length)
    try:
        raw = _inflate(record, chunk)
    except _INFLATE_ERRORS as err:
        if isinstance(err, McapIndexError):
            raise
        reason = (str(err).splitlines() or [type(err).__name__])[0]
        msg = f"corrupt chunk at offset {chunk.offset} holding {topics}: {reason}"
        raise McapIndexError(msg) from None
    return raw, _pread_exact(fd, file_size, chunk.offset + chunk.length, chunk.index_length)


def _pread_exact(fd: int, file_size: int, offset: int, size: int) -> bytes:
    if offset < 0 or size < 0 or offset + size > file_size:  # a corrupt index: no huge read
        msg = (
            f"corrupt MCAP index: a record of {size} bytes at offset {offset} would reach "
            f"beyond the file's {file_size} bytes"
        )
        raise McapIndexError(msg)
    data = os.pread(fd, size, offset)
    if len(data) != size:
        msg = f"truncated record at offset {offset}"
        raise McapIndexError(msg)
    return data


def _inflate(record: bytes, chunk: McapChunk) -> bytes:
    if len(record) < 9 + 28 or record[0] != 0x06:
        msg = f"no chunk at offset {chunk.offset}"
        raise McapIndexError(msg)
    _, _, size, crc = struct.unpack_from("<QQQI", record, 9)
    compression, pos = mcap_string(record, 9 + 28)
    (packed,) = struct.unpack_from("<Q", record, pos)
    data = record[pos + 8 : pos + 8 + packed]
    if len(data) != packed:
        msg = f"truncated chunk at offset {chunk.offset}"
        raise McapIndexError(msg)
    return decompress(data, compression, size, crc)


def _cut(
    raw: bytes, entries: NDArray[np.uint64], channel: int
) -> tuple[NDArray[np.uint64], list[bytes]]:
    """Log times and payloads of the message records at ``entries[:, 1]`` in ``raw``."""
    n = entries.shape[0]
    if n == 0:
        return np.zeros(0, dtype=np.uint64), []
    offsets = entries[:, 1].astype(np.int64)
    if int(offsets.max()) + _MESSAGE_HEADER > len(raw) or int(offsets.min()) < 0:
        msg = f"message index of channel {channel} points outside its chunk"
        raise McapIndexError(msg)
    u8 = np.frombuffer(raw, dtype=np.uint8)
    header = u8[offsets[:, None] + np.arange(_MESSAGE_HEADER)]
    lengths = np.ascontiguousarray(header[:, 1:9]).view("<u8").ravel().astype(np.int64)
    cids = np.ascontiguousarray(header[:, 9:11]).view("<u2").ravel()
    times = np.ascontiguousarray(header[:, 15:23]).view("<u8").ravel()
    ends = offsets + 9 + lengths
    bad = (header[:, 0] != _OP_MESSAGE) | (cids != channel) | (lengths < 22) | (ends > len(raw))
    if bool(np.any(bad)) or not np.array_equal(times, entries[:, 0]):
        msg = f"message index of channel {channel} does not match its messages"
        raise McapIndexError(msg)
    starts = (offsets + _MESSAGE_HEADER).tolist()
    payloads = [raw[s:e] for s, e in zip(starts, ends.tolist(), strict=True)]
    return times.astype(np.uint64), payloads
