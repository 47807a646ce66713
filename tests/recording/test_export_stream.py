"""Streaming export (``omnical export`` of a bag): part by part, the same bytes as the whole-table
export of ``read_bag``, whatever the bag (chunks, ROS 1, dirty times, several connections), and a
bag found corrupt half-way leaves the output directory as it was."""

from __future__ import annotations

import csv
import io
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from recording_samples import T0_NS, sample_recording
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

from omnical.bags import ros1chunks
from omnical.bags.bag import indexed_mcap, read_bag, write_bag
from omnical.bags.export import (
    csv_rows,
    export_bag_csv,
    export_bag_tum,
    export_csv,
    export_tum,
)
from omnical.bags.ros1chunks import LeanRos1Reader
from omnical.bags.stream import BagStream
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM

TUM_TOPICS = (ODOM, GROUND_TRUTH, HEDGE_POS_ANG)


def _files(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


@dataclass(frozen=True)
class WholeTable:
    """The whole-table export of a bag (``read_bag``, then ``export_csv`` / ``export_tum``)."""

    csv: list[str]  # file names, in the order written
    tum: list[str]
    csv_files: dict[str, bytes]
    tum_files: dict[str, bytes]
    notes: tuple[str, ...]
    topics: set[str]


def _whole_table(bag: Path, tmp_path: Path) -> WholeTable:
    recording = read_bag(bag)
    whole = export_csv(recording, tmp_path / "w")
    whole_tum = export_tum(read_bag(bag, TUM_TOPICS), tmp_path / "tw")
    return WholeTable(
        [p.name for p in whole],
        [p.name for p in whole_tum],
        _files(tmp_path / "w"),
        _files(tmp_path / "tw"),
        recording.notes,
        {t for t in recording.tables if recording.has(t)},
    )


def _same_as_whole_table(
    bag: Path, tmp_path: Path, batch: int, whole: WholeTable | None = None
) -> None:
    """CSV and TUM streamed with ``batch`` == the whole-table export, byte for byte (``whole``:
    that export of ``bag`` made once for several batches)."""
    if whole is None:
        whole = _whole_table(bag, tmp_path)
    streamed = export_bag_csv(bag, tmp_path / "s", batch=batch)
    assert [p.name for p in streamed.written] == whole.csv
    assert _files(tmp_path / "s") == whole.csv_files
    assert streamed.notes == whole.notes
    assert streamed.topics == whole.topics
    tum = export_bag_tum(bag, tmp_path / "ts", batch=batch)
    assert [p.name for p in tum.written] == whole.tum
    assert _files(tmp_path / "ts") == whole.tum_files


def _big_recording() -> Recording:
    """Every canonical topic, enough rows for several 1 MiB MCAP chunks (scans: 7 ranges)."""
    recording = sample_recording(np.random.default_rng(41), n=9_000)
    hedge = recording.topic(HEDGE_POS_ANG)
    n = len(hedge)
    columns = {k: hedge[k] for k in hedge.names} | {
        "flags": np.where(np.arange(n) % 5 == 0, 1, 0).astype(np.uint8),
        "address": (np.arange(n) % 3 + 7).astype(np.uint8),  # three hedgehogs
    }
    return recording.with_table(HEDGE_POS_ANG, Table(hedge.t_ns, columns))


@pytest.fixture(scope="module")
def chunked_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_bag(_big_recording(), tmp_path_factory.mktemp("chunked") / "run")


def test_a_bag_of_several_chunks_is_read_part_by_part(chunked_bag: Path) -> None:
    summary = indexed_mcap(chunked_bag)
    assert summary is not None and len(summary.chunks) >= 3
    # a message record is at least 31 bytes: a bound of the messages of one chunk
    per_chunk = max(c.uncompressed_size // 31 for c in summary.chunks)
    stream = BagStream(chunked_bag, batch=500)
    sizes: dict[str, list[int]] = {}
    for part in stream.parts():
        sizes.setdefault(part.topic, []).append(len(part.table))
        assert len(part.table) < 500 + per_chunk
    recording = read_bag(chunked_bag)
    assert set(sizes) == set(recording.tables) and stream.topics == list(recording.tables)
    assert stream.whole == []
    for topic, table in recording.tables.items():
        assert sum(sizes[topic]) == len(table)
        if len(table) > 2_000:
            assert len(sizes[topic]) >= 4, topic  # never the whole topic at once


@pytest.fixture(scope="module")
def chunked_whole(chunked_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> WholeTable:
    return _whole_table(chunked_bag, tmp_path_factory.mktemp("whole"))


@pytest.mark.parametrize("batch", [1, 333, 100_000])
def test_a_chunked_bag_streams_to_the_same_files_as_the_whole_table_path(
    chunked_bag: Path, chunked_whole: WholeTable, tmp_path: Path, batch: int
) -> None:
    _same_as_whole_table(chunked_bag, tmp_path, batch, chunked_whole)


def test_a_ros1_bag_streams_chunk_by_chunk_to_the_same_files(tmp_path: Path) -> None:
    bag = write_bag(_big_recording(), tmp_path / "run.bag")
    with LeanRos1Reader(bag) as reader:
        assert len(reader.chunk_infos) >= 3
        assert reader.indexes == {c.id: [] for c in reader.connections}  # none in memory
        per_chunk = max(sum(i.connection_counts.values()) for i in reader.chunk_infos)
    stream = BagStream(bag, batch=500)
    assert all(len(p.table) < 500 + per_chunk for p in stream.parts())
    assert stream.whole == []
    _same_as_whole_table(bag, tmp_path, batch=777)


def _foreign_bag(path: Path, connections: list[tuple[str, str, list[tuple[int, Any]]]]) -> Path:
    """A ROS 2 MCAP bag written by rosbags itself, messages in the order given."""
    store = typestore(2)
    with Writer2(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype, messages in connections:
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for t_ns, message in messages:
                writer.write(conn, t_ns, store.serialize_cdr(message, msgtype))
    return path


def _twist(vx: float) -> Any:
    types = typestore(2).types
    vec = types["geometry_msgs/msg/Vector3"]
    return types["geometry_msgs/msg/Twist"](
        linear=vec(x=vx, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.5)
    )


def _hedge(address: int, x: float, flags: int = 0) -> Any:
    cls = typestore(2).types["marvelmind_ros2_msgs/msg/HedgePositionAngle"]
    return cls(address=address, timestamp_ms=7, x_m=x, y_m=-x, z_m=0.5, flags=flags, angle=3.0)


def test_duplicates_and_bad_rows_across_part_boundaries_are_cleaned_as_read_bag(
    tmp_path: Path,
) -> None:
    values = [0.1, 0.1, 0.1, 0.2, float("nan"), float("nan"), 1e300, 0.3, 0.3, 0.4]
    times = [T0_NS + k for k in (0, 0, 0, 1, 2, 2, 3, 4, 4, 4)]
    bag = _foreign_bag(
        tmp_path / "dups",
        [
            (
                "/cmd_vel",
                "geometry_msgs/msg/Twist",
                [(t, _twist(v)) for t, v in zip(times, values, strict=True)],
            )
        ],
    )
    for batch in (1, 2, 3, 100):
        _same_as_whole_table(bag, tmp_path / f"b{batch}", batch)
    stream = BagStream(bag, batch=1)
    rows = sum(len(p.table) for p in stream.parts())
    assert rows == 4 and stream.whole == []
    assert stream.notes == read_bag(bag).notes != ()


def test_topics_back_in_time_or_of_several_connections_are_read_whole(tmp_path: Path) -> None:
    back = [(T0_NS + t, _twist(0.1 * t)) for t in (0, 1, 2, 5, 3, 4, 6, 6)]
    one = [(T0_NS + 2 * k, _hedge(3, 0.1 * k, flags=k % 2)) for k in range(6)]
    two = [(T0_NS + 2 * k + 1, _hedge(4, -0.2 * k)) for k in range(6)]
    quality_cls = typestore(2).types["marvelmind_ros2_msgs/msg/HedgeQuality"]
    quality = [(T0_NS + k, quality_cls(address=3, quality_percents=k)) for k in range(5)]
    ahead = [(T0_NS + k, _twist(0.0)) for k in range(4)]
    bag = _foreign_bag(
        tmp_path / "dirty",
        [
            ("/cmd_vel", "geometry_msgs/msg/Twist", back),
            ("/hedge1/hedge_pos_ang", "marvelmind_ros2_msgs/msg/HedgePositionAngle", one),
            ("/hedge2/hedge_pos_ang", "marvelmind_ros2_msgs/msg/HedgePositionAngle", two),
            ("/cmd_vel_other", "geometry_msgs/msg/Twist", ahead),  # not read
            ("/hedge3/hedge_quality", "marvelmind_ros2_msgs/msg/HedgeQuality", quality),
        ],
    )
    for batch in (1, 2, 100):
        _same_as_whole_table(bag, tmp_path / f"b{batch}", batch)
    stream = BagStream(bag, batch=2)
    firsts = [p.topic for p in stream.parts() if p.first]
    assert stream.whole == ["/cmd_vel", HEDGE_POS_ANG]
    assert stream.topics == ["/cmd_vel", HEDGE_POS_ANG, "/hedge_quality"]
    assert firsts.count("/cmd_vel") == 1 and firsts.count(HEDGE_POS_ANG) == 1
    assert any("out of time order" in n for n in stream.notes)


def test_a_bag_corrupt_half_way_leaves_the_output_directory_as_it_was(
    chunked_bag: Path, tmp_path: Path
) -> None:
    summary = indexed_mcap(chunked_bag)
    assert summary is not None
    chunk = summary.chunks[len(summary.chunks) // 2]
    data = bytearray(summary.path.read_bytes())
    middle = chunk.offset + chunk.length // 2
    data[middle : middle + 64] = bytes(64)  # the chunk's compressed data
    broken = tmp_path / "broken"
    broken.mkdir()
    for f in chunked_bag.iterdir():
        (broken / f.name).write_bytes(data if f == summary.path else f.read_bytes())
    out = tmp_path / "out"
    out.mkdir()
    (out / "odom.csv").write_text("an earlier export\n", encoding="utf-8")
    for export in (export_bag_csv, export_bag_tum):
        with pytest.raises(RecordingError, match="cannot read bag") as err:
            export(broken, out, batch=100)
        assert "\n" not in str(err.value) and str(broken) in str(err.value)
        assert _files(out) == {"odom.csv": b"an earlier export\n"}


def test_csv_rows_are_what_csv_writer_writes() -> None:
    floats = np.array([0.1, -0.0, 1e16, 1e-7, 123456789.125, np.inf, -np.inf, np.nan, 5e-324])
    columns = [
        np.arange(floats.size, dtype=np.int64) * 10**17,
        floats,
        floats.astype(np.float32),
        np.arange(floats.size, dtype=np.uint8) * 31,
        np.array([True, False] * 4 + [True]),
    ]
    expected = io.StringIO()
    csv.writer(expected).writerows(zip(*(c.tolist() for c in columns), strict=True))
    assert csv_rows(columns) == expected.getvalue()
    texts = np.array(["a,b", 'say "hi"', "two\nlines", "", "plain", "ä", " ", "\r", "x"], object)
    expected = io.StringIO()
    csv.writer(expected).writerows(zip(columns[0].tolist(), texts.tolist(), strict=True))
    assert csv_rows([columns[0], texts]) == expected.getvalue()
    assert csv_rows([np.zeros(0), np.zeros(0)]) == ""


def _ros1_record(fields: list[tuple[bytes, bytes]], data: bytes) -> bytes:
    header = b"".join(struct.pack("<I", len(k) + 1 + len(v)) + k + b"=" + v for k, v in fields)
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def test_ros1_records_of_another_layout_or_behind_a_connection_record_are_cut_one_by_one() -> None:
    def message(conn: int, sec: int, data: bytes, *, reverse: bool = False) -> bytes:
        fields = [
            (b"op", b"\x02"),
            (b"conn", struct.pack("<I", conn)),
            (b"time", struct.pack("<II", sec, 5)),
        ]
        return _ros1_record(fields[::-1] if reverse else fields, data)

    connection = _ros1_record(
        [(b"op", b"\x07"), (b"conn", struct.pack("<I", 3)), (b"topic", b"/x")], b"type=x"
    )
    records = [
        connection + message(3, 1, b"first"),  # the index points at the connection record
        message(3, 2, b"second"),
        message(4, 2, b"other connection"),
        message(3, 3, b"third", reverse=True),  # another field order
        message(3, 4, b"fourth"),
    ]
    offsets = np.cumsum([0] + [len(r) for r in records[:-1]])
    raw = b"".join(records)
    mine = [0, 1, 3, 4]
    entries = np.zeros(len(mine), dtype=ros1chunks._ENTRY)
    entries["sec"] = [1, 2, 3, 4]
    entries["nsec"] = 5
    entries["offset"] = offsets[mine]
    assert ros1chunks._cut(raw, entries, 3) == [b"first", b"second", b"third", b"fourth"]
    entries["sec"][1] = 9  # the index says another time than the record
    with pytest.raises(ros1chunks.Ros1ChunkError, match="does not match"):
        ros1chunks._cut(raw, entries, 3)
    entries["sec"][1] = 2
    entries["offset"][2] = offsets[2]  # another connection's record
    with pytest.raises(ros1chunks.Ros1ChunkError, match="does not match"):
        ros1chunks._cut(raw, entries, 3)


def test_hidden_files_of_a_killed_export_are_swept_and_earlier_files_replaced(
    tmp_path: Path,
) -> None:
    bag = write_bag(sample_recording(np.random.default_rng(43), n=20), tmp_path / "run")
    out = tmp_path / "out"
    out.mkdir()
    (out / ".odom.csv.omnical-partial-3").write_text("killed", encoding="utf-8")
    (out / "odom.csv").write_text("an earlier export\n", encoding="utf-8")
    written = export_bag_csv(bag, out).written
    assert not list(out.glob(".*"))
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in written)
    assert (out / "odom.csv").read_text(encoding="utf-8").startswith("t_ns,x_m,")
