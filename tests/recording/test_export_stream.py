"""Streaming export (``omnical export`` of a bag): part by part, the same bytes as in one part a
topic, those files parsed as CSV / TUM ``read_bag``'s rows, whatever the bag (chunks, ROS 1,
dirty times, several connections); a bag corrupt half-way leaves the output directory as it was."""

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
from omnical.bags.bag import BagStream, indexed_mcap, read_bag, write_bag
from omnical.bags.export import csv_rows, export_bag_csv, export_bag_tum
from omnical.bags.ros1chunks import LeanRos1Reader
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import HEDGE_POS_ANG


def _files(directory: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(directory.iterdir())}


_ONE_PART = 1 << 62
"""A batch no topic reaches: every topic is decoded and handed over in one part."""


@dataclass(frozen=True)
class _Whole:
    """A bag exported in one part a topic: its CSV and TUM files as written, and the bytes of
    each directory's files."""

    csv_written: list[str]
    csv: dict[str, bytes]
    tum_written: list[str]
    tum: dict[str, bytes]
    notes: tuple[str, ...]
    topics: frozenset[str]


_WHOLE: dict[Path, _Whole] = {}
"""Per bag, its one-part export, checked once against ``read_bag`` (the files streamed in any
batch are compared with it byte for byte: what holds for these holds for them)."""


def _whole(bag: Path, tmp_path: Path) -> _Whole:
    """The bag's one-part export, its CSV files ``read_bag``'s rows and its TUM files its poses."""
    if bag in _WHOLE:
        return _WHOLE[bag]
    whole = export_bag_csv(bag, tmp_path / "w", batch=_ONE_PART)
    recording = read_bag(bag)
    assert whole.notes == recording.notes
    assert whole.topics == {t for t in recording.tables if recording.has(t)}
    with_rows = [t for t in recording.tables if recording.has(t)]
    assert [p.name for p in whole.written] == [
        t.strip("/").replace("/", "_") + ".csv" for t in with_rows
    ]
    for topic, path in zip(with_rows, whole.written, strict=True):
        _csv_holds(path, recording.topic(topic))
    tum = export_bag_tum(bag, tmp_path / "tw", batch=_ONE_PART)
    _tum_holds(tum.written, recording)
    _WHOLE[bag] = _Whole(
        [p.name for p in whole.written],
        _files(tmp_path / "w"),
        [p.name for p in tum.written],
        _files(tmp_path / "tw"),
        whole.notes,
        whole.topics,
    )
    return _WHOLE[bag]


def _same_as_whole_table(bag: Path, tmp_path: Path, batch: int) -> None:
    """CSV and TUM streamed with ``batch`` == streamed in one part a topic, byte for byte, and
    the CSV files hold ``read_bag``'s rows (checked once a bag, on the one-part files)."""
    whole = _whole(bag, tmp_path)
    streamed = export_bag_csv(bag, tmp_path / "s", batch=batch)
    assert [p.name for p in streamed.written] == whole.csv_written
    assert _files(tmp_path / "s") == whole.csv
    assert streamed.notes == whole.notes
    assert streamed.topics == whole.topics
    tum = export_bag_tum(bag, tmp_path / "ts", batch=batch)
    assert [p.name for p in tum.written] == whole.tum_written
    assert _files(tmp_path / "ts") == whole.tum


def _csv_holds(path: Path, table: Table) -> None:
    """The CSV file of a topic, read back with :mod:`csv`, is ``table`` (``read_bag``'s): every
    column, value for value (floats read back exactly; 2-D columns as NAME.0, NAME.1, ...)."""
    header, *rows = list(csv.reader(io.StringIO(path.read_text(encoding="utf-8"))))
    fields = list(zip(*rows, strict=True)) if rows else [()] * len(header)
    assert header[0] == "t_ns"
    np.testing.assert_array_equal(np.array(fields[0], dtype=np.int64), table.t_ns)
    expected: dict[str, np.ndarray[Any, Any]] = {}
    for name in table.names:
        values = np.asarray(table[name])
        if values.ndim == 1:
            expected[name] = values
        else:
            expected.update({f"{name}.{i}": values[:, i] for i in range(values.shape[1])})
    assert header[1:] == list(expected), path
    for name, text in zip(header[1:], fields[1:], strict=True):
        values = expected[name]
        if values.dtype.kind == "f":
            read = np.array([float(v) for v in text], dtype=np.float64)
            np.testing.assert_array_equal(read, values.astype(np.float64), err_msg=name)
        elif values.dtype.kind in "iu":
            assert [int(v) for v in text] == values.tolist(), name
        else:  # text, booleans: as str() writes them
            assert list(text) == [str(v) for v in values.tolist()], name


def _tum_holds(files: tuple[Path, ...], recording: Recording) -> None:
    """The TUM files, parsed as TUM (t tx ty tz qx qy qz qw), are the recording's odometry and
    ground truth (planar: yaw as a quaternion about z) and each hedgehog's valid positions."""

    def parse(path: Path) -> tuple[list[int], np.ndarray[Any, Any]]:
        lines = [ln.split() for ln in path.read_text(encoding="utf-8").splitlines()]
        assert all(len(ln) == 8 for ln in lines), path
        stamps = [int(ln[0].replace(".", "")) for ln in lines]  # seconds with nine decimals
        assert all(len(ln[0].split(".")[1]) == 9 for ln in lines)
        return stamps, np.array([[float(v) for v in ln[1:]] for ln in lines])

    by_name = {p.name: p for p in files}
    expected = []
    for topic in ("/odom", "/ground_truth"):
        if recording.has(topic):
            name = topic.strip("/") + ".tum"
            expected.append(name)
            stamps, rows = parse(by_name[name])
            table = recording.topic(topic)
            assert stamps == table.t_ns.tolist()
            np.testing.assert_array_equal(rows[:, 0], table["x_m"])
            np.testing.assert_array_equal(rows[:, 1], table["y_m"])
            assert not rows[:, 2:5].any()
            np.testing.assert_allclose(np.hypot(rows[:, 5], rows[:, 6]), 1.0, rtol=1e-15)
            yaw = 2.0 * np.arctan2(rows[:, 5], rows[:, 6])
            turn = np.angle(np.exp(1j * (yaw - np.asarray(table["yaw_rad"]))))
            np.testing.assert_allclose(turn, 0.0, atol=1e-12)
    if recording.has(HEDGE_POS_ANG):
        hedge = recording.topic(HEDGE_POS_ANG)
        valid = (np.asarray(hedge["flags"]) & 1) == 0
        addresses = sorted(set(np.asarray(hedge["address"])[valid].tolist()))
        for address in addresses:
            name = "hedge_pos_ang.tum" if len(addresses) == 1 else f"hedge_pos_ang_{address}.tum"
            expected.append(name)
            mine = valid & (np.asarray(hedge["address"]) == address)
            stamps, rows = parse(by_name[name])
            assert stamps == hedge.t_ns[mine].tolist()
            for k, column in enumerate(("x_m", "y_m", "z_m")):
                np.testing.assert_array_equal(rows[:, k], np.asarray(hedge[column])[mine])
            np.testing.assert_array_equal(rows[:, 3:], [[0.0, 0.0, 0.0, 1.0]] * int(mine.sum()))
    assert sorted(by_name) == sorted(expected)


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


@pytest.mark.parametrize("batch", [1, 333, 100_000])
def test_a_chunked_bag_streams_to_the_same_files_as_the_whole_table_path(
    chunked_bag: Path, tmp_path: Path, batch: int
) -> None:
    _same_as_whole_table(chunked_bag, tmp_path, batch)


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
