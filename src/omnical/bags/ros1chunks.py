"""Chunk-by-chunk reading of an indexed ROS 1 bag, without an in-memory index of every message.

:class:`LeanRos1Reader` is rosbags' reader with the per-message index left on disk (put it in
``AnyReader.readers``); :func:`chunk_messages` yields the wanted messages a chunk at a time.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Collection, Iterator
from typing import Any, Final

import numpy as np
from numpy.typing import NDArray
from rosbags.rosbag1 import Reader as Ros1Reader
from rosbags.rosbag1.reader import Header, RecordType, read_uint32

__all__ = ["LeanRos1Reader", "Ros1ChunkError", "chunk_messages"]

_OP_MSGDATA: Final = 0x02
_OP_CONNECTION: Final = 0x07
_ENTRY = np.dtype([("sec", "<u4"), ("nsec", "<u4"), ("offset", "<u4")])


class Ros1ChunkError(ValueError):
    """A chunk, its index or a message record of a ROS 1 bag is malformed or truncated."""


class LeanRos1Reader(Ros1Reader):
    """rosbags' ROS 1 reader keeping, instead of every message's index entry, where each
    chunk's index records are: ``index_records[chunk_pos]`` = [(conn, count, data position)]."""

    def __init__(self, path: Any) -> None:
        super().__init__(path)
        self.index_records: dict[int, list[tuple[int, int, int]]] = {}

    def read_index_data(self, pos: int, indexes: Any) -> None:
        """Note where the index record at the current position is, and skip it."""
        assert self.bio
        header = Header.read(self.bio, RecordType.IDXDATA)
        if header.get_uint32("ver") != 1:
            msg = "IDXDATA version is not supported"
            raise Ros1ChunkError(msg)
        conn, count = header.get_uint32("conn"), header.get_uint32("count")
        size = read_uint32(self.bio)
        if size != 12 * count:
            msg = f"index record of connection {conn} has {size} bytes for {count} messages"
            raise Ros1ChunkError(msg)
        self.index_records.setdefault(pos, []).append((conn, count, self.bio.tell()))
        self.bio.seek(size, os.SEEK_CUR)


def chunk_messages(
    reader: LeanRos1Reader, connections: Collection[int]
) -> Iterator[tuple[int, NDArray[np.uint64], list[bytes]]]:
    """The messages of ``connections`` (ids), chunk by chunk: (conn, times ns, payloads).

    Raises:
        Ros1ChunkError: An index or a record is malformed or truncated.
        OSError: The file cannot be read.
    """
    wanted = set(connections)
    bio = reader.bio
    assert bio is not None
    for info in reader.chunk_infos:
        records = [r for r in reader.index_records.get(info.pos, []) if r[0] in wanted]
        if not records:
            continue
        chunk = reader.chunks[info.pos]
        bio.seek(chunk.datapos)
        packed = bio.read(chunk.datasize)
        if len(packed) != chunk.datasize:
            msg = f"truncated chunk at offset {info.pos}"
            raise Ros1ChunkError(msg)
        raw = chunk.decompressor(packed)
        for conn, count, datapos in sorted(records):
            bio.seek(datapos)
            data = bio.read(12 * count)
            if len(data) != 12 * count:
                msg = f"truncated index of connection {conn}"
                raise Ros1ChunkError(msg)
            entries = np.frombuffer(data, dtype=_ENTRY)
            times = entries["sec"].astype(np.uint64) * np.uint64(10**9) + entries["nsec"]
            yield conn, times, _cut(raw, entries, conn)


def _fields(raw: bytes, pos: int) -> tuple[dict[bytes, tuple[int, int]], int]:
    """The header fields of the record at ``pos`` (name → value start, end) and its end."""
    (length,) = struct.unpack_from("<I", raw, pos)
    pos += 4
    end = pos + length
    if end > len(raw):
        msg = "record header runs past its chunk"
        raise Ros1ChunkError(msg)
    fields: dict[bytes, tuple[int, int]] = {}
    while pos < end:
        (size,) = struct.unpack_from("<I", raw, pos)
        field = raw[pos + 4 : pos + 4 + size]
        name, sep, _ = field.partition(b"=")
        if not sep or pos + 4 + size > end:
            msg = "malformed record header"
            raise Ros1ChunkError(msg)
        start = pos + 4 + len(name) + 1
        fields[name] = (start, pos + 4 + size)
        pos += 4 + size
    return fields, end


def _message_at(raw: bytes, pos: int, conn: int, t_ns: int) -> bytes:
    """The payload of the message record at ``pos`` (connection records before it skipped)."""
    try:
        while True:
            fields, end = _fields(raw, pos)
            op = raw[slice(*fields[b"op"])]
            (size,) = struct.unpack_from("<I", raw, end)
            if op != bytes([_OP_CONNECTION]):
                break
            pos = end + 4 + size
        sec, nsec = struct.unpack_from("<II", raw, fields[b"time"][0])
        (got,) = struct.unpack_from("<I", raw, fields[b"conn"][0])
    except (KeyError, struct.error):
        msg = f"malformed message record of connection {conn}"
        raise Ros1ChunkError(msg) from None
    if op != bytes([_OP_MSGDATA]) or got != conn or sec * 10**9 + nsec != t_ns:
        msg = f"index of connection {conn} does not match its messages"
        raise Ros1ChunkError(msg)
    if end + 4 + size > len(raw):
        msg = f"message record of connection {conn} runs past its chunk"
        raise Ros1ChunkError(msg)
    return raw[end + 4 : end + 4 + size]


def _cut(raw: bytes, entries: NDArray[Any], conn: int) -> list[bytes]:
    """Payloads of the message records at ``entries['offset']`` in ``raw``.

    Records whose header has the first one's layout are cut all at once, others one by one.
    """
    n = entries.shape[0]
    if n == 0:
        return []
    offsets = entries["offset"].astype(np.int64)
    times = entries["sec"].astype(np.int64) * 10**9 + entries["nsec"]
    first = _first_layout(raw, int(offsets[0]), conn)
    payloads: list[bytes | None] = [None] * n
    if first is not None and int(offsets.max()) + 4 + len(first[0]) + 4 <= len(raw):
        template, mask, time_at = first
        u8 = np.frombuffer(raw, dtype=np.uint8)
        hl = len(template)
        head = u8[offsets[:, None] + np.arange(4 + hl + 4)]
        fits = np.all((head[:, 4 : 4 + hl] == template) | ~mask, axis=1)
        fits &= np.ascontiguousarray(head[:, :4]).view("<u4").ravel() == hl
        stamp = np.ascontiguousarray(head[:, 4 + time_at : 4 + time_at + 8]).view("<u4")
        fits &= stamp[:, 0].astype(np.int64) * 10**9 + stamp[:, 1] == times
        sizes = np.ascontiguousarray(head[:, 4 + hl :]).view("<u4").ravel().astype(np.int64)
        starts = offsets + 8 + hl
        fits &= starts + sizes <= len(raw)
        for i, s, e in zip(
            np.flatnonzero(fits).tolist(),
            starts[fits].tolist(),
            (starts + sizes)[fits].tolist(),
            strict=True,
        ):
            payloads[i] = raw[s:e]
    for i, payload in enumerate(payloads):
        if payload is None:
            payloads[i] = _message_at(raw, int(offsets[i]), conn, int(times[i]))
    return payloads  # type: ignore[return-value]


def _first_layout(
    raw: bytes, pos: int, conn: int
) -> tuple[NDArray[np.uint8], NDArray[np.bool_], int] | None:
    """The header of the message record at ``pos`` if it is one of ``conn``: its bytes, the mask
    of the bytes every such header shares (all but the time), and where the time is."""
    try:
        fields, end = _fields(raw, pos)
        op = raw[slice(*fields[b"op"])]
        (got,) = struct.unpack_from("<I", raw, fields[b"conn"][0])
        time_at = fields[b"time"][0] - pos - 4
    except (KeyError, struct.error, Ros1ChunkError):
        return None
    if op != bytes([_OP_MSGDATA]) or got != conn or fields[b"time"][1] - fields[b"time"][0] != 8:
        return None
    template = np.frombuffer(raw[pos + 4 : end], dtype=np.uint8)
    mask = np.ones(template.size, dtype=bool)
    mask[time_at : time_at + 8] = False
    return template, mask, time_at
