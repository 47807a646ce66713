"""The bulk MCAP writer: its bags read as rosbags' writer's do, and every record is well formed.

Three independent readers check what :func:`omnical.bags.sink.write_ros2_bag` writes:
rosbags' ``AnyReader`` (against the same recording written through rosbags' ``Writer``),
the ``mcap`` package (Foxglove's reader, CRCs validated), and :func:`parse_mcap` below, a
strict reader of the MCAP specification written for this test alone.
"""

from __future__ import annotations

import struct
import sys
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from recording_samples import T0_NS, assert_recordings_equal, column_values, sample_recording
from rosbags.highlevel import AnyReader

from omnical.bags import baginfo as baginfo_module
from omnical.bags.bag import BagWriter, foreign_bag_reason, read_bag, write_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.mcapwrite import McapWriter
from omnical.bags.sink import (
    OMNICAL_MARKER,
    OMNICAL_MARKER_KEY,
    BagCompression,
    write_ros2_bag,
)
from omnical.recording.recording import Recording, RecordingBuilder, Table
from omnical.recording.topics import TOPICS

if sys.version_info >= (3, 14):
    from compression import zstd
else:
    from backports import zstd

MAGIC = b"\x89MCAP0\r\n"


class MalformedError(AssertionError):
    """The file breaks the MCAP specification."""


def _check(ok: bool, what: str) -> None:
    if not ok:
        raise MalformedError(what)


@dataclass
class _Reader:
    """Little-endian fields of one record's content, refusing to run past its end."""

    data: bytes
    pos: int = 0

    def take(self, n: int) -> bytes:
        _check(self.pos + n <= len(self.data), "field runs past its record")
        out = self.data[self.pos : self.pos + n]
        self.pos += n
        return out

    def u8(self) -> int:
        return self.take(1)[0]

    def u16(self) -> int:
        return int(struct.unpack("<H", self.take(2))[0])

    def u32(self) -> int:
        return int(struct.unpack("<I", self.take(4))[0])

    def u64(self) -> int:
        return int(struct.unpack("<Q", self.take(8))[0])

    def string(self) -> str:
        return self.take(self.u32()).decode("utf-8")

    def string_map(self) -> dict[str, str]:
        inner = _Reader(self.take(self.u32()))
        out = {}
        while not inner.done():
            key = inner.string()
            _check(key not in out, "duplicate map key")
            out[key] = inner.string()
        return out

    def pairs(self, fmt: str) -> list[tuple[int, int]]:
        size = struct.calcsize(fmt)
        raw = self.take(self.u32())
        _check(len(raw) % size == 0, "array length not a multiple of its element")
        return [(int(a), int(b)) for a, b in struct.iter_unpack(fmt, raw)]

    def done(self) -> bool:
        return self.pos == len(self.data)

    def end(self, what: str) -> None:
        _check(self.done(), f"{what}: trailing bytes")


def _records(data: bytes, start: int, stop: int) -> list[tuple[int, int, bytes]]:
    """(offset, opcode, content) of the records filling ``data[start:stop]`` exactly."""
    out = []
    pos = start
    while pos < stop:
        _check(pos + 9 <= stop, f"record header at {pos} runs past its section")
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        _check(op != 0, "opcode 0")
        _check(pos + 9 + length <= stop, f"record at {pos} runs past its section")
        out.append((pos, op, data[pos + 9 : pos + 9 + length]))
        pos += 9 + length
    return out


@dataclass
class ParsedMcap:
    """What :func:`parse_mcap` found: header, schemas and channels by id, messages as
    (channel id, sequence, log time, publish time, data) in file order, metadata, statistics."""

    profile: str
    library: str
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    channels: dict[int, tuple[int, str, str, dict[str, str]]] = field(default_factory=dict)
    messages: list[tuple[int, int, int, int, bytes]] = field(default_factory=list)
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    chunk_count: int = 0
    compressions: set[str] = field(default_factory=set)
    chunks: list[tuple[int, str, int, int, bytes]] = field(default_factory=list)
    """(offset, compression, CRC, uncompressed size, body) of each Chunk record."""

    def by_time(self) -> list[tuple[str, int, bytes]]:
        """(topic, log time, data) sorted by log time (ties in file order)."""
        rows = [(self.channels[c][1], t, d) for c, _, t, _, d in self.messages]
        return sorted(rows, key=lambda r: r[1])


def parse_mcap(data: bytes) -> ParsedMcap:
    """Read ``data`` as the MCAP specification says, checking every record and index.

    Raises:
        MalformedError: Anything the specification forbids or the indexes contradict.
    """
    _check(data[:8] == MAGIC and data[-8:] == MAGIC, "magic")
    _check(len(data) >= 8 + 9 + 20 + 8, "too short")
    footer_at = len(data) - 8 - 29
    footer = _Reader(data[footer_at : len(data) - 8])
    _check(footer.u8() == 0x02 and footer.u64() == 20, "footer record")
    summary_start, offsets_start, summary_crc = footer.u64(), footer.u64(), footer.u32()
    first = _records(data, 8, 8 + 9 + struct.unpack_from("<Q", data, 9)[0])
    _check(len(first) == 1 and first[0][1] == 0x01, "first record is not a Header")
    header = _Reader(first[0][2])
    parsed = ParsedMcap(header.string(), header.string())
    header.end("header")
    _check(8 < summary_start <= offsets_start <= footer_at, "summary offsets")
    data_records = _records(data, 9 + len(first[0][2]) + 8, summary_start)
    _check(data_records[-1][1] == 0x0F, "the data section does not end with Data End")
    chunks: dict[int, dict[str, Any]] = {}
    metadata_at: dict[int, tuple[int, str]] = {}
    current: dict[str, Any] | None = None
    seen_data_end = False
    for offset, op, content in data_records:
        _check(not seen_data_end, "records after Data End")
        r = _Reader(content)
        if op == 0x07:
            _check(current is not None, "message index not after a chunk")
            assert current is not None
            cid = r.u16()
            entries = r.pairs("<QQ")
            r.end("message index")
            _check(cid not in current["indexes"], "two message indexes for one channel")
            current["indexes"][cid] = (offset, entries)
            current["index_end"] = offset + 9 + len(content)
            continue
        current = None
        if op == 0x06:
            start, end, size, crc = r.u64(), r.u64(), r.u64(), r.u32()
            compression = r.string()
            body = r.take(r.u64())
            r.end("chunk")
            _check(compression in ("", "zstd"), f"compression {compression!r}")
            raw = zstd.decompress(body) if compression == "zstd" else body
            _check(len(raw) == size, "chunk uncompressed size")
            _check(crc == 0 or zlib.crc32(raw) == crc, "chunk CRC")
            parsed.compressions.add(compression)
            parsed.chunk_count += 1
            parsed.chunks.append((offset, compression, crc, size, body))
            inner: dict[int, list[tuple[int, int]]] = {}
            for pos, iop, icontent in _records(raw, 0, len(raw)):
                _parse_plain(parsed, iop, icontent, pos, inner, inside_chunk=True)
            times = [t for entries in inner.values() for t, _ in entries]
            _check((start, end) == ((min(times), max(times)) if times else (0, 0)), "chunk times")
            current = {
                "offset": offset,
                "length": 9 + len(content),
                "start": start,
                "end": end,
                "compression": compression,
                "compressed": len(body),
                "size": size,
                "messages": inner,
                "indexes": {},
                "index_end": offset + 9 + len(content),
            }
            chunks[offset] = current
        elif op in (0x03, 0x04, 0x05):
            _parse_plain(parsed, op, content, offset, {}, inside_chunk=False)
        elif op == 0x0C:
            name = r.string()
            parsed.metadata[name] = r.string_map()
            r.end("metadata")
            metadata_at[offset] = (9 + len(content), name)
        elif op == 0x0F:
            r.u32()
            r.end("data end")
            seen_data_end = True
        else:
            raise MalformedError(f"opcode {op:#x} in the data section")
    for chunk in chunks.values():  # one index per channel, listing exactly its messages
        _check(set(chunk["indexes"]) == set(chunk["messages"]), "message indexes vs channels")
        for cid, (_, entries) in chunk["indexes"].items():
            _check(sorted(entries) == sorted(chunk["messages"][cid]), "message index entries")
            _check(entries == sorted(entries), "message index not in log-time order")
    summary = _records(data, summary_start, offsets_start or footer_at)
    groups: dict[int, tuple[int, int]] = {}
    for offset, op, content in summary:
        if op in groups:
            _check(groups[op][1] == offset, f"summary records of {op:#x} not grouped")
            groups[op] = (groups[op][0], offset + 9 + len(content))
        else:
            groups[op] = (offset, offset + 9 + len(content))
    _check(set(groups) <= {0x03, 0x04, 0x08, 0x0A, 0x0B, 0x0D}, "summary opcodes")
    offsets = _records(data, offsets_start, footer_at) if offsets_start else []
    stated = {}
    for _, op, content in offsets:
        _check(op == 0x0E, "not a summary offset record")
        r = _Reader(content)
        group = r.u8()
        stated[group] = (r.u64(), r.u64())
        r.end("summary offset")
    _check(stated == {op: (a, b - a) for op, (a, b) in groups.items()}, "summary offsets")
    _check(
        summary_crc == 0 or zlib.crc32(data[summary_start : footer_at + 1 + 8 + 16]) == summary_crc,
        "summary CRC",
    )
    indexed_chunks = {}
    stats = None
    metadata_index = {}
    for _, op, content in summary:
        r = _Reader(content)
        if op == 0x03:
            sid = r.u16()
            _check(parsed.schemas.get(sid) == (r.string(), r.string(), r.take(r.u32())), "schema")
        elif op == 0x04:
            cid, sid = r.u16(), r.u16()
            channel = (sid, r.string(), r.string(), r.string_map())
            _check(parsed.channels.get(cid) == channel, "summary channel differs")
        elif op == 0x08:
            start, end, offset, length = r.u64(), r.u64(), r.u64(), r.u64()
            index_offsets = dict(r.pairs("<HQ"))
            index_length, compression = r.u64(), r.string()
            compressed, size = r.u64(), r.u64()
            chunk = chunks.get(offset)
            _check(chunk is not None, "chunk index points at no chunk")
            assert chunk is not None
            _check(
                (start, end, length, compression, compressed, size)
                == (
                    chunk["start"],
                    chunk["end"],
                    chunk["length"],
                    chunk["compression"],
                    chunk["compressed"],
                    chunk["size"],
                ),
                "chunk index fields",
            )
            _check(
                index_offsets == {c: o for c, (o, _) in chunk["indexes"].items()},
                "message index offsets",
            )
            _check(index_length == chunk["index_end"] - offset - length, "message index length")
            indexed_chunks[offset] = chunk
        elif op == 0x0B:
            stats = (r.u64(), r.u16(), r.u32(), r.u32(), r.u32(), r.u32(), r.u64(), r.u64())
            stats_counts = dict(r.pairs("<HQ"))
        elif op == 0x0D:
            offset, length, name = r.u64(), r.u64(), r.string()
            metadata_index[offset] = (length, name)
        r.end(f"summary record {op:#x}")
    _check(indexed_chunks.keys() == chunks.keys(), "a chunk without index")
    _check(metadata_index == metadata_at, "metadata index")
    _check(stats is not None, "no statistics")
    assert stats is not None
    times = [m[2] for m in parsed.messages]
    counts: dict[int, int] = dict.fromkeys(parsed.channels, 0)
    for m in parsed.messages:
        counts[m[0]] += 1
    _check(
        stats
        == (
            len(parsed.messages),
            len(parsed.schemas),
            len(parsed.channels),
            0,
            len(parsed.metadata),
            len(chunks),
            min(times, default=0),
            max(times, default=0),
        ),
        "statistics",
    )
    _check(stats_counts == counts, "statistics channel counts")
    return parsed


def _parse_plain(
    parsed: ParsedMcap,
    op: int,
    content: bytes,
    offset: int,
    inner: dict[int, list[tuple[int, int]]],
    *,
    inside_chunk: bool,
) -> None:
    """A Schema, Channel or Message record (inside a chunk only those may appear)."""
    r = _Reader(content)
    if op == 0x03:
        sid = r.u16()
        schema = (r.string(), r.string(), r.take(r.u32()))
        r.end("schema")
        _check(sid != 0 and parsed.schemas.get(sid, schema) == schema, "schema id")
        parsed.schemas[sid] = schema
    elif op == 0x04:
        cid, sid = r.u16(), r.u16()
        channel = (sid, r.string(), r.string(), r.string_map())
        r.end("channel")
        _check(sid in parsed.schemas, "channel before its schema")
        _check(parsed.channels.get(cid, channel) == channel, "channel id reused")
        parsed.channels[cid] = channel
    elif op == 0x05:
        _check(len(content) >= 22, "message record too short")
        cid, seq = r.u16(), r.u32()
        log_time, publish_time = r.u64(), r.u64()
        _check(cid in parsed.channels, "message before its channel")
        parsed.messages.append((cid, seq, log_time, publish_time, content[22:]))
        inner.setdefault(cid, []).append((log_time, offset))
    else:
        where = "a chunk" if inside_chunk else "the data section"
        raise MalformedError(f"opcode {op:#x} in {where}")


def _storage(location: Path) -> Path:
    return location / f"{location.name}.mcap"


def _any_reader(location: Path) -> tuple[set[tuple[Any, ...]], list[tuple[str, int, bytes]]]:
    with AnyReader([location]) as reader:
        connections = {
            (c.id, c.topic, c.msgtype, c.msgdef.format, c.msgdef.data, c.digest, c.msgcount)
            for c in reader.connections
        }
        messages = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    return connections, messages


def _both(
    tmp_path: Path, recording: Recording, compression: BagCompression | None = "auto"
) -> tuple[Path, Path]:
    """``recording`` written by the bulk writer and by rosbags' writer."""
    writers: tuple[BagWriter, BagWriter] = ("bulk", "rosbags")
    bulk, base = (
        write_bag(recording, tmp_path / f"{w}.mcap", compression=compression, writer=w)
        for w in writers
    )
    return bulk, base


def _metadata(location: Path) -> dict[str, Any]:
    info = yaml.safe_load((location / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    name = _storage(location).name
    assert info["relative_file_paths"] == [name]
    assert info["files"][0]["path"] == name
    info["relative_file_paths"] = info["files"][0]["path"] = "*"
    info.pop("ros_distro")
    return dict(info)


@pytest.fixture
def recording() -> Recording:
    return sample_recording(np.random.default_rng(21), n=60)


@pytest.mark.parametrize("compression", ["auto", None])
def test_bulk_bag_reads_as_the_rosbags_one(
    tmp_path: Path, recording: Recording, compression: BagCompression | None
) -> None:
    bulk, base = _both(tmp_path, recording, compression)
    assert _any_reader(bulk) == _any_reader(base)  # every message, its time, connections
    assert_recordings_equal(read_bag(bulk), recording)
    assert_recordings_equal(read_bag(bulk), read_bag(base))
    assert _metadata(bulk) == _metadata(base)
    parsed, baseline = (
        parse_mcap(_storage(bulk).read_bytes()),
        parse_mcap(_storage(base).read_bytes()),
    )
    assert parsed.compressions == ({"zstd"} if compression else {""})
    assert parsed.by_time() == baseline.by_time()
    assert (parsed.profile, baseline.profile) == ("ros2", "ros2")
    assert parsed.library.startswith("omnical-")
    assert parsed.schemas == baseline.schemas  # ros2msg definitions
    assert parsed.channels == baseline.channels  # cdr, offered_qos_profiles
    embedded = yaml.safe_load(parsed.metadata["rosbag2"]["serialized_metadata"])
    on_disk = yaml.safe_load((bulk / "metadata.yaml").read_text())
    assert embedded == on_disk["rosbag2_bagfile_information"]
    assert embedded["custom_data"][OMNICAL_MARKER_KEY] == OMNICAL_MARKER
    assert foreign_bag_reason(bulk) is None


@pytest.mark.parametrize("compression", ["auto", None])
def test_mcap_reader_reads_every_message(
    tmp_path: Path, recording: Recording, compression: BagCompression | None
) -> None:
    mcap_reader = pytest.importorskip("mcap.reader")
    bulk, base = _both(tmp_path, recording, compression)
    _, expected = _any_reader(base)
    with _storage(bulk).open("rb") as stream:
        reader = mcap_reader.make_reader(stream, validate_crcs=True)
        summary = reader.get_summary()
        got = [
            (channel.topic, message.log_time, message.data)
            for _, channel, message in reader.iter_messages(log_time_order=True)
        ]
        header = reader.get_header()
    assert got == expected
    assert header.profile == "ros2"
    assert summary.statistics.message_count == recording.message_count
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == set(recording.tables)
    for topic, channel in topics.items():
        assert channel.message_encoding == "cdr"
        assert channel.metadata == {"offered_qos_profiles": ""}
        schema = summary.schemas[channel.schema_id]
        assert (schema.name, schema.encoding) == (TOPICS[topic].ros2_type, "ros2msg")
        assert summary.statistics.channel_message_counts[channel.id] == len(recording.topic(topic))


def test_small_chunks_and_windows(tmp_path: Path, recording: Recording) -> None:
    """Many chunks, encoded a few messages at a time: the same messages, in order."""
    _, base = _both(tmp_path, recording)
    custom = {OMNICAL_MARKER_KEY: OMNICAL_MARKER}
    location = tmp_path / "small"
    write_ros2_bag(location, recording.tables, "zstd", custom, chunk_size=3000, window=7)
    parsed = parse_mcap(_storage(location).read_bytes())
    assert parsed.chunk_count > recording.message_count // 7
    assert _any_reader(location) == _any_reader(base)
    assert_recordings_equal(read_bag(location), recording)


def test_ties_and_rows_out_of_order(tmp_path: Path) -> None:
    """Equal times across topics keep the topic order; a table's rows are sorted by time."""
    rng = np.random.default_rng(3)
    t = T0_NS + np.array([5, 1, 3, 3, 0, 5], dtype=np.int64) * 10**6
    tables = {}
    for topic in ("/odom", "/cmd_vel", "/imu"):
        values = column_values(TOPICS[topic], t.size, rng)
        tables[topic] = Table(t if topic != "/imu" else np.sort(t), values)
    recording = Recording(tables)
    bulk, base = _both(tmp_path, recording)
    assert _any_reader(bulk) == _any_reader(base)
    parse_mcap(_storage(bulk).read_bytes())


def test_joint_states_with_differing_names(tmp_path: Path) -> None:
    """A JointState topic whose joint names change: records of several sizes in one topic."""
    rng = np.random.default_rng(4)
    builder = RecordingBuilder()
    n = 9
    names = np.array(
        [["l", "r"] if i % 3 else ["left_wheel", "right"] for i in range(n)], dtype=object
    )
    builder.add_many(
        "/dead_wheels",
        T0_NS + np.arange(n, dtype=np.int64) * 10**7,
        name=names,
        position_rad=rng.normal(size=(n, 2)),
        velocity_radps=rng.normal(size=(n, 2)),
        effort_nm=np.zeros((n, 0)),
    )
    recording = builder.build()
    bulk, base = _both(tmp_path, recording)
    assert _any_reader(bulk) == _any_reader(base)
    parse_mcap(_storage(bulk).read_bytes())


def test_empty_topics_and_an_empty_recording(tmp_path: Path, recording: Recording) -> None:
    odom = recording.topic("/odom")
    with_empty = recording.with_table("/odom", odom.take(np.arange(0)))
    bulk, base = _both(tmp_path / "a", with_empty)
    connections, messages = _any_reader(bulk)
    assert (connections, messages) == _any_reader(base)
    assert "/odom" not in {c[1] for c in connections}  # a topic without rows is not written
    assert not read_bag(bulk).has("/odom")
    empty = Recording({"/odom": odom.take(np.arange(0))})
    bulk, base = _both(tmp_path / "b", empty)
    assert _any_reader(bulk) == _any_reader(base) == (set(), [])
    assert read_bag(bulk).message_count == 0
    assert _metadata(bulk) == _metadata(base)
    parsed = parse_mcap(_storage(bulk).read_bytes())
    assert (parsed.messages, parsed.chunk_count, parsed.channels) == ([], 0, {})
    assert summarize_bag(bulk) == summarize_bag(base)


def test_info_comes_from_the_summary_and_custom_data(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    bulk, base = _both(tmp_path, recording)
    expected = summarize_bag(base)

    def no_decoding(*_a: object, **_k: object) -> None:
        raise AssertionError("info decoded a topic")

    monkeypatch.setattr(baginfo_module, "read_bag", no_decoding)
    got = summarize_bag(bulk)
    assert got.topics == expected.topics
    assert got.duration_s == expected.duration_s
    assert got.distance_odom_m == pytest.approx(expected.distance_odom_m, rel=1e-12)
    assert got.distance_ground_truth_m == pytest.approx(expected.distance_ground_truth_m, rel=1e-12)
    assert got.final_pose_odom == expected.final_pose_odom
    assert got.distance_odom_m is not None
    assert got.distance_ground_truth_m is not None


def test_a_bug_while_finishing_surfaces_and_leaves_no_partial_bag(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    def bug(self: McapWriter) -> None:
        raise RuntimeError("bug")

    monkeypatch.setattr(McapWriter, "finish", bug)
    with pytest.raises(RuntimeError, match="bug"):
        write_bag(recording, tmp_path / "run.mcap")
    assert list(tmp_path.iterdir()) == []


def _zstd_frame(body: bytes) -> tuple[int | None, bool]:
    """Content size stated by the zstd frame ``body`` (None if not stated) and whether the
    frame ends with a content checksum (RFC 8878, section 3.1.1.1)."""
    _check(body[:4] == b"\x28\xb5\x2f\xfd", "zstd frame magic")
    descriptor = body[4]
    fcs_flag, single, dict_flag = descriptor >> 6, (descriptor >> 5) & 1, descriptor & 3
    at = 5 + (0 if single else 1) + (0, 1, 2, 4)[dict_flag]
    fcs_size = (1 if single else 0, 2, 4, 8)[fcs_flag]
    if not fcs_size:
        return None, bool(descriptor & 0x04)
    size = int.from_bytes(body[at : at + fcs_size], "little") + (256 if fcs_size == 2 else 0)
    return size, bool(descriptor & 0x04)


def test_zstd_chunks_carry_the_frame_checksum_instead_of_a_crc(
    tmp_path: Path, recording: Recording
) -> None:
    """A zstd chunk states CRC 0 ("not computed") and is one zstd frame stating its size and
    ending with the XXH64 checksum of its records, which the decoders check."""
    location = tmp_path / "run"
    write_ros2_bag(location, recording.tables, "zstd", {}, chunk_size=4000, window=50)
    data = _storage(location).read_bytes()
    parsed = parse_mcap(data)
    assert len(parsed.chunks) > 1
    for _, compression, crc, size, body in parsed.chunks:
        assert (compression, crc) == ("zstd", 0)
        assert _zstd_frame(body) == (size, True)
    offset, _, _, _, body = parsed.chunks[1]
    checksum_at = data.index(body, offset) + len(body) - 4  # the frame's last 4 bytes
    bad = _patched(data, checksum_at, bytes(b ^ 0xFF for b in body[-4:]))
    with pytest.raises(zstd.ZstdError, match="checksum"):
        parse_mcap(bad)
    _storage(location).write_bytes(bad)
    with pytest.raises(zstd.ZstdError, match="checksum"):
        _any_reader(location)


def test_uncompressed_chunks_state_their_crc(tmp_path: Path, recording: Recording) -> None:
    location = write_bag(recording, tmp_path / "plain.mcap", compression=None)
    parsed = parse_mcap(_storage(location).read_bytes())  # checks each nonzero CRC
    assert parsed.chunks
    assert all(compression == "" and crc != 0 for _, compression, crc, _, _ in parsed.chunks)


def _patched(data: bytes, at: int, raw: bytes) -> bytes:
    return data[:at] + raw + data[at + len(raw) :]


def test_the_parser_refuses_malformed_records(tmp_path: Path, recording: Recording) -> None:
    """parse_mcap is strict: each of these defects of a good file is caught."""
    location = write_bag(recording, tmp_path / "plain.mcap", compression=None)
    good = _storage(location).read_bytes()
    parse_mcap(good)
    chunk_at = next(o for o, op, _ in _records(good, 8, len(good) - 37) if op == 0x06)
    crc_at = chunk_at + 9 + 24
    records_at = chunk_at + 9 + 8 + 8 + 8 + 4 + 4 + 8  # uncompressed: the records start here
    no_crc = _patched(good, crc_at, bytes(4))  # so that the structure itself is checked
    index_at = next(o for o, op, _ in _records(good, 8, len(good) - 37) if op == 0x07)
    (summary_start,) = struct.unpack_from("<Q", good, len(good) - 8 - 20)
    defects = {
        "a chunk's CRC": _patched(good, crc_at, b"\x01\x00\x00\x00"),
        "an opcode in a chunk": _patched(no_crc, records_at, b"\x7f"),
        "a record length in a chunk": _patched(no_crc, records_at + 1, b"\x01"),
        "a message index offset": _patched(good, index_at + 9 + 2 + 4 + 8, b"\x07"),
        "a message index time": _patched(good, index_at + 9 + 2 + 4, b"\x07"),
        "the summary start": _patched(
            good, len(good) - 8 - 20, struct.pack("<Q", summary_start + 1)
        ),
        "the summary CRC": _patched(good, len(good) - 8 - 4, b"\x00\x00\x00\x01"),
        "a cut file": good[: len(good) // 2] + good[-37:],
    }
    for what, bad in defects.items():
        with pytest.raises((MalformedError, zstd.ZstdError, UnicodeDecodeError, struct.error)):
            parse_mcap(bad)
            pytest.fail(f"not caught: {what}")
