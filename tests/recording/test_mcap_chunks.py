"""channel_messages over many chunks: every message once, in order; a corrupt chunk or index
a clear error, never a huge read; another writer's file read as its own reader reads it."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from backports.zstd import ZstdError
from recording_samples import T0_NS, column_values

from omnical.bags.bag import read_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.mcapindex import (
    McapChunk,
    McapIndexError,
    McapSummary,
    channel_messages,
    mcap_records,
    read_summary,
)
from omnical.bags.messages import encode_table
from omnical.bags.recover import bag_is_complete
from omnical.bags.sink import write_ros2_bag
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import spec_of


def _bag(tmp_path: Path, n: int = 3_000) -> Path:
    """An IMU bag of many small zstd chunks."""
    spec = spec_of("/imu")
    assert spec is not None
    t_ns = T0_NS + np.arange(n, dtype=np.int64) * 10_000_000
    table = Table(t_ns, column_values(spec, n, np.random.default_rng(1)))
    location = tmp_path / "imu"
    write_ros2_bag(location, {"/imu": table}, "zstd", {}, chunk_size=20_000, window=50)
    return location


def _storage(location: Path) -> Path:
    return next(location.glob("*.mcap"))


def test_every_message_once_in_order_across_many_chunks(tmp_path: Path) -> None:
    location = _bag(tmp_path)
    summary = read_summary(_storage(location))
    assert summary is not None and len(summary.chunks) > 20
    (channel,) = summary.channels
    times = [t for _, t, _ in channel_messages(summary, [channel])]
    joined = np.concatenate(times).astype(np.int64)
    assert joined.size == 3_000
    assert np.all(np.diff(joined) > 0)
    assert np.array_equal(read_bag(location).topic("/imu").t_ns, joined)


def _spoil_a_chunk(
    storage: Path, spoil: Callable[[bytes], bytes], size: int
) -> tuple[McapSummary, McapChunk, bytes]:
    """``size`` bytes in the middle of the sixth chunk of ``storage`` replaced by ``spoil`` of
    them: the summary (as it was), that chunk and the spoilt file's bytes."""
    summary = read_summary(storage)
    assert summary is not None
    chunk = summary.chunks[5]
    data = bytearray(storage.read_bytes())
    middle = chunk.offset + chunk.length // 2
    data[middle : middle + size] = spoil(bytes(data[middle : middle + size]))
    storage.write_bytes(bytes(data))
    return summary, chunk, bytes(data)


def test_a_corrupt_chunk_read_ahead_is_reported_by_the_caller(tmp_path: Path) -> None:
    """A chunk spoilt after the first ones: the messages before it come, then the error,
    which read_bag reports as an unreadable bag."""
    location = _bag(tmp_path)
    storage = _storage(location)
    summary, _, _ = _spoil_a_chunk(storage, lambda part: bytes(len(part)), 64)
    taken = 0
    with pytest.raises((McapIndexError, ZstdError)):
        for _, t_ns, _ in channel_messages(summary, list(summary.channels)):
            taken += t_ns.size
    assert 0 < taken < 3_000
    with pytest.raises(RecordingError, match="cannot read bag"):
        read_bag(location)


def test_recording_unchanged(tmp_path: Path) -> None:
    """Read through the read-ahead: the same table as written."""
    spec = spec_of("/imu")
    assert spec is not None
    location = _bag(tmp_path, 500)
    table = read_bag(location).topic("/imu")
    expected = column_values(spec, 500, np.random.default_rng(1))
    for name, values in expected.items():
        assert np.array_equal(table[name], values), name
    assert isinstance(read_bag(location), Recording)


def test_a_chunk_index_reaching_past_the_file_is_not_read(tmp_path: Path) -> None:
    """A chunk index claiming 2⁴⁰ bytes (a corrupt summary) is a clear error, not an attempt
    to allocate a terabyte."""
    from dataclasses import replace

    summary = read_summary(_storage(_bag(tmp_path)))
    assert summary is not None
    chunks = list(summary.chunks)
    chunks[2] = replace(chunks[2], length=1 << 40)
    spoilt = replace(summary, chunks=tuple(chunks))
    with pytest.raises(McapIndexError, match=r"at offset \d+ would reach beyond the file's"):
        for _ in channel_messages(spoilt, list(summary.channels)):
            pass


def _flip_chunk_index_field(storage: Path, k: int, field: int) -> None:
    """Invert the 8 bytes of field ``field`` (0 start, 1 end, 2 offset, 3 length) of the
    ``k``-th chunk index record in the summary of ``storage``, as a bad disk block would."""
    data = bytearray(storage.read_bytes())
    summary_start = int.from_bytes(data[-8 - 20 : -8 - 12], "little")  # the footer's field
    records = mcap_records(bytes(data), summary_start, len(data))
    bodies = [body for op, body, _ in records if op == 0x08]
    at = bodies[k] + 8 * field
    data[at : at + 8] = bytes(b ^ 0xFF for b in data[at : at + 8])
    storage.write_bytes(bytes(data))


@pytest.mark.parametrize("field", [2, 3])
def test_a_chunk_index_pointing_outside_the_file_says_so(tmp_path: Path, field: int) -> None:
    """Found by a new user: a flipped chunk offset in the summary gave "cannot read bag
    (McapIndexError: truncated record at offset 18446744073708352424)". The offset read from
    the file is checked against the file, and the message says what is wrong, in words."""
    location = _bag(tmp_path)
    storage = _storage(location)
    size = storage.stat().st_size
    _flip_chunk_index_field(storage, 4, field)
    with pytest.raises(McapIndexError) as err:
        read_summary(storage)
    if field == 2:
        assert re.fullmatch(
            rf".*: corrupt MCAP summary: chunk index 5 puts its chunk at offset \d+, "
            rf"beyond the file's {size} bytes",
            str(err.value),
        ), err.value
    else:
        assert "outside the data section (bytes 8 to " in str(err.value)
    for read in (read_bag, summarize_bag):
        with pytest.raises(RecordingError) as info:
            read(location)
        message = str(info.value)
        assert message.startswith(f"{location}: cannot read bag ({storage}: corrupt MCAP summary")
        assert "McapIndexError" not in message and "truncated" not in message


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_a_file_of_foxgloves_writer_reads_as_its_own_reader_reads_it(
    tmp_path: Path, compression: str
) -> None:
    """The index reader on another writer's layout (``mcap``'s Writer: channels interleaved
    in each chunk, CRCs, any chunk compression): one topic selected, the messages ``mcap``'s
    reader gives, and read_bag's table is the one written."""
    mcap_writer = pytest.importorskip("mcap.writer")
    mcap_reader = pytest.importorskip("mcap.reader")
    store = typestore(2)
    rng = np.random.default_rng(3)
    tables = {}
    for topic, period_ns in (("/imu", 10_000_000), ("/odom", 20_000_000)):
        spec = spec_of(topic)
        assert spec is not None
        n = 600 if topic == "/imu" else 300
        tables[topic] = (spec, Table(T0_NS + np.arange(n) * period_ns, column_values(spec, n, rng)))
    path = tmp_path / "foreign.mcap"
    kind = {"zstd": "ZSTD", "lz4": "LZ4", "": "NONE"}[compression]
    with path.open("wb") as stream:
        writer = mcap_writer.Writer(
            stream, chunk_size=8_000, compression=mcap_writer.CompressionType[kind]
        )
        writer.start(profile="ros2", library="test")
        messages = []
        for topic, (spec, table) in tables.items():
            msgdef, _ = store.generate_msgdef(spec.ros2_type, ros_version=2)
            sid = writer.register_schema(spec.ros2_type, "ros2msg", msgdef.encode())
            cid = writer.register_channel(topic, "cdr", sid)
            payloads = encode_table(spec, table, 2)
            messages += [(int(t), cid, bytes(p)) for t, p in zip(table.t_ns, payloads, strict=True)]
        for t, cid, data in sorted(messages):
            writer.add_message(cid, t, data, t)
        writer.finish()
    summary = read_summary(path)
    assert summary is not None and len(summary.chunks) > 5
    imu = next(c for c in summary.channels.values() if c.topic == "/imu")
    assert {c.compression for c in summary.chunks} == {compression}
    got = [
        (int(t), bytes(p))
        for _, times, payloads in channel_messages(summary, [imu.id])
        for t, p in zip(times, payloads, strict=True)
    ]
    with path.open("rb") as stream:
        reader = mcap_reader.make_reader(stream, validate_crcs=True)
        expected = [(m.log_time, m.data) for _, _, m in reader.iter_messages(topics=["/imu"])]
    assert got == expected and len(got) == 600
    table = read_bag(path, ["/imu"]).topic("/imu")
    written = tables["/imu"][1]
    assert np.array_equal(table.t_ns, written.t_ns)
    for name in written.names:
        assert np.array_equal(table[name], written[name]), name


def test_a_corrupt_chunk_of_a_complete_file_is_damage_not_an_interruption(tmp_path: Path) -> None:
    """Found by a new user: 8 bytes flipped in a chunk of a complete, indexed MCAP gave
    "cannot read bag (ZstdError: ...); if its recording was interrupted, `omnical recover`
    salvages what was flushed", and `omnical recover` answered "is complete: nothing to
    recover". The message names the chunk and says the file is damaged; only a file without
    its summary (an interrupted recording) is sent to `omnical recover`."""
    location = _bag(tmp_path)
    storage = _storage(location)
    summary, chunk, data = _spoil_a_chunk(storage, lambda part: bytes(b ^ 0xFF for b in part), 8)
    assert bag_is_complete(location)  # what `omnical recover` goes by
    with pytest.raises(RecordingError) as info:
        read_bag(location)
    message = str(info.value)
    assert message.startswith(
        f"{location}: cannot read bag (corrupt chunk at offset {chunk.offset} holding /imu: "
    )
    assert message.endswith(
        "the file is complete (closed with its index) but damaged: `omnical recover` cannot mend it"
    )
    assert "salvages" not in message and "Error" not in message
    storage.write_bytes(bytes(data[: summary.chunks[-1].offset]))  # no summary: interrupted
    assert not bag_is_complete(location)
    with pytest.raises(RecordingError, match=r"`omnical recover` salvages what was flushed$"):
        read_bag(location)
