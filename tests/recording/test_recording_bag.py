"""Bag round trips, the on-disk rule, third-party recordings and bad input."""

from __future__ import annotations

import os
import re
import sqlite3
import threading
from collections.abc import Callable, Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import numpy as np
import pytest
from recording_samples import (
    T0_NS,
    assert_recordings_equal,
    column_values,
    oracle_bytes,
    sample_recording,
)
from rosbags.highlevel import AnyReader
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

from omnical.bags.bag import BagStream, BagWriter, bag_location, read_bag, write_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.mcapwrite import McapWriter
from omnical.bags.recover import bag_is_complete, recover_bag
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import RecordingBuilder, Table
from omnical.recording.topics import TOPICS


@pytest.fixture
def recording():  # type: ignore[no-untyped-def]
    return sample_recording(np.random.default_rng(11))


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
def test_round_trip_every_topic(tmp_path: Path, recording, name: str) -> None:  # type: ignore[no-untyped-def]
    location = write_bag(recording, tmp_path / name)
    back = read_bag(location)
    assert_recordings_equal(recording, back)
    assert dict(back.skipped_topics) == {}


def test_on_disk_rule(tmp_path: Path, recording) -> None:  # type: ignore[no-untyped-def]
    assert bag_location("out/RUN.mcap") == Path("out/RUN")
    assert bag_location("out/RUN") == Path("out/RUN")
    assert bag_location("out/RUN.bag") == Path("out/RUN.bag")
    location = write_bag(recording, tmp_path / "RUN.mcap")
    assert location == tmp_path / "RUN"
    assert sorted(p.name for p in location.iterdir()) == ["RUN.mcap", "metadata.yaml"]
    # the path given to write_bag reads back too, and so does the inner standalone MCAP file
    assert_recordings_equal(recording, read_bag(tmp_path / "RUN.mcap"))
    assert_recordings_equal(recording, read_bag(location / "RUN.mcap"))
    assert [p.name for p in tmp_path.iterdir()] == ["RUN"]  # no staging left behind


@pytest.mark.parametrize("name", ["plain.mcap", "plain.bag"])
def test_plain_anyreader_sees_documented_topics_and_types(
    tmp_path: Path, recording, name: str
) -> None:  # type: ignore[no-untyped-def]
    location = write_bag(recording, tmp_path / name)
    ros = 1 if name.endswith(".bag") else 2
    with AnyReader([location]) as reader:
        topics = {t: (info.msgtype, info.msgcount) for t, info in reader.topics.items()}
        first = next(reader.messages())
        odom = [c for c in reader.connections if c.topic == "/odom"]
        message = reader.deserialize(
            next(reader.messages(connections=odom))[2], "nav_msgs/msg/Odometry"
        )
    expected = {
        spec.name: (spec.ros2_type if ros == 2 else spec.ros1_type, len(recording.topic(spec.name)))
        for spec in TOPICS.values()
    }
    assert topics == expected
    assert first[1] == recording.start_ns  # global time order
    assert message.header.frame_id == "odom"  # type: ignore[attr-defined]
    assert message.child_frame_id == "base_link"  # type: ignore[attr-defined]


def test_write_refuses_to_overwrite_unless_asked(tmp_path: Path, recording) -> None:  # type: ignore[no-untyped-def]
    write_bag(recording, tmp_path / "a.mcap")
    with pytest.raises(RecordingError, match="already exists"):
        write_bag(recording, tmp_path / "a.mcap")
    smaller = recording.without("/imu")
    write_bag(smaller, tmp_path / "a.mcap", overwrite=True)
    assert not read_bag(tmp_path / "a").has("/imu")
    write_bag(recording, tmp_path / "b.bag")
    write_bag(smaller, tmp_path / "b.bag", overwrite=True)
    assert not read_bag(tmp_path / "b.bag").has("/imu")
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("years of work")
    with pytest.raises(RecordingError, match=r"not a bag omnical wrote .*; refusing"):
        write_bag(recording, precious, overwrite=True)
    assert (precious / "chapter1.tex").read_text() == "years of work"


def test_an_alias_bomb_in_metadata_yaml_is_refused_unexpanded(tmp_path: Path, recording) -> None:  # type: ignore[no-untyped-def]
    """Issue 28: every YAML reader refuses aliases, a bag's metadata.yaml included."""
    location = write_bag(recording, tmp_path / "a.mcap")
    meta = location / "metadata.yaml"
    levels = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    levels += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * 9)}]" for i in range(1, 9)]
    meta.write_text("\n".join(levels) + "\n" + meta.read_text())
    with pytest.raises(RecordingError, match=r"not a bag omnical wrote .*alias"):
        write_bag(recording, tmp_path / "a.mcap", overwrite=True)
    assert meta.read_text().startswith("a0: &a0")


def test_write_rejects_unknown_topics_and_negative_times(tmp_path: Path) -> None:
    builder = RecordingBuilder()
    builder.add("/wheels", 1, w1_radps=1.0)
    with pytest.raises(RecordingError, match="cannot write topic /wheels"):
        write_bag(builder.build(), tmp_path / "x.mcap")
    negative = RecordingBuilder()
    negative.add("/cmd_vel", -5, vx_mps=0.0, vy_mps=0.0, wz_radps=0.0)
    with pytest.raises(RecordingError, match="negative time"):
        write_bag(negative.build(), tmp_path / "x.mcap")
    assert list(tmp_path.iterdir()) == []


def _write_third_party_ros2(path: Path, storage: StoragePlugin) -> dict[str, Table]:
    """A recording as another tool would make it: other names, TwistStamped, extra topics."""
    store = typestore(2)
    rng = np.random.default_rng(5)
    tables: dict[str, Table] = {}
    with Writer2(path, version=9, storage_plugin=storage) as writer:
        for topic, canonical in [("/hedge1/hedgehog_pos_ang", "/hedge_pos_ang"), ("odom", "/odom")]:
            spec = TOPICS[canonical]
            table = Table(T0_NS + np.arange(4, dtype=np.int64) * 10**8, column_values(spec, 4, rng))
            tables[topic] = table
            conn = writer.add_connection(topic, spec.ros2_type, typestore=store)
            for i in range(4):
                writer.write(conn, int(table.t_ns[i]), oracle_bytes(spec, table, i, 2))
        conn = writer.add_connection("cmd_vel", "geometry_msgs/msg/TwistStamped", typestore=store)
        types = store.types
        for i in range(3):
            header = types["std_msgs/msg/Header"](
                stamp=types["builtin_interfaces/msg/Time"](sec=i, nanosec=0), frame_id="base_link"
            )
            vec = types["geometry_msgs/msg/Vector3"]
            twist = types["geometry_msgs/msg/Twist"](
                linear=vec(x=0.1 * i, y=-0.2, z=0.0), angular=vec(x=0.0, y=0.0, z=0.3)
            )
            msg = types["geometry_msgs/msg/TwistStamped"](header=header, twist=twist)
            writer.write(conn, T0_NS + i, bytes(store.serialize_cdr(msg, conn.msgtype)))
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        msg = types["std_msgs/msg/String"](data="hi")
        writer.write(conn, T0_NS, bytes(store.serialize_cdr(msg, conn.msgtype)))
    return tables


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_third_party_ros2_topics_recognised_by_type_and_name(
    tmp_path: Path, storage: StoragePlugin
) -> None:
    tables = _write_third_party_ros2(tmp_path / "theirs", storage)
    rec = read_bag(tmp_path / "theirs")
    assert set(rec.topics) == {"/hedge_pos_ang", "/odom", "/cmd_vel"}
    assert dict(rec.skipped_topics) == {"/chatter": "std_msgs/msg/String"}
    hedge = rec.topic("/hedge_pos_ang")
    np.testing.assert_array_equal(hedge["x_m"], tables["/hedge1/hedgehog_pos_ang"]["x_m"])
    np.testing.assert_array_equal(hedge["address"], tables["/hedge1/hedgehog_pos_ang"]["address"])
    np.testing.assert_array_equal(rec.topic("/odom")["vy_mps"], tables["odom"]["vy_mps"])
    np.testing.assert_allclose(rec.topic("/cmd_vel")["vx_mps"], [0.0, 0.1, 0.2])
    np.testing.assert_array_equal(rec.topic("/cmd_vel")["wz_radps"], [0.3, 0.3, 0.3])


def test_sqlite_bag_streamed_in_parts_of_two_joins_into_read_bag(tmp_path: Path) -> None:
    """A SQLite bag goes through rosbags, batched per connection: parts of two rows put end to
    end are ``read_bag``'s tables, and nothing is read whole."""
    _write_third_party_ros2(tmp_path / "theirs", StoragePlugin.SQLITE3)
    whole = read_bag(tmp_path / "theirs")
    stream = BagStream(tmp_path / "theirs", batch=2)
    parts: dict[str, list[Table]] = {}
    for part in stream.parts():
        assert len(part.table) <= 2
        parts.setdefault(part.topic, []).append(part.table)
    assert stream.topics == list(whole.topics) and stream.whole == []
    assert dict(stream.skipped) == dict(whole.skipped_topics) and stream.notes == whole.notes
    for topic, tables in parts.items():
        assert len(tables) == -(-len(whole.topic(topic)) // 2)
        np.testing.assert_array_equal(
            np.concatenate([t.t_ns for t in tables]), whole.topic(topic).t_ns
        )
        for name in whole.topic(topic).names:
            joined = np.concatenate([t[name] for t in tables])
            np.testing.assert_array_equal(joined, whole.topic(topic)[name])


def test_third_party_ros1_names_and_two_hedgehogs_merge(tmp_path: Path) -> None:
    store = typestore(1)
    spec = TOPICS["/hedge_pos_ang"]
    rng = np.random.default_rng(8)
    path = tmp_path / "theirs.bag"
    times = {"hedge_pos_ang": [0, 20, 40], "/hedge2/hedge_pos_ang": [10, 30]}
    with Writer1(path) as writer:
        for topic, ts in times.items():
            values = column_values(spec, len(ts), rng)
            values["address"] = np.full(len(ts), 1 if "2" not in topic else 2, dtype=np.uint8)
            table = Table(T0_NS + np.array(ts, dtype=np.int64), values)
            conn = writer.add_connection(topic, spec.ros1_type, typestore=store)
            for i in range(len(ts)):
                writer.write(conn, int(table.t_ns[i]), oracle_bytes(spec, table, i, 1))
    hedge = read_bag(path).topic("/hedge_pos_ang")
    np.testing.assert_array_equal(hedge.t_ns - T0_NS, [0, 10, 20, 30, 40])
    np.testing.assert_array_equal(hedge["address"], [1, 2, 1, 2, 1])


@pytest.mark.parametrize("name", ["cut.mcap", "cut.bag"])
def test_truncated_bag_raises_recording_error_naming_the_file(
    tmp_path: Path, recording, name: str
) -> None:  # type: ignore[no-untyped-def]
    location = write_bag(recording, tmp_path / name)
    data_file = location / f"{location.name}.mcap" if location.is_dir() else location
    data = data_file.read_bytes()
    data_file.write_bytes(data[: len(data) // 2])
    with pytest.raises(RecordingError, match=re.escape(f"{location}: cannot read bag")) as info:
        read_bag(location)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("name", ["garbage.mcap", "garbage.bag", "garbage.db3", "notes.txt"])
def test_garbage_file_raises_recording_error(tmp_path: Path, name: str) -> None:
    path = tmp_path / name
    path.write_bytes(np.random.default_rng(1).bytes(5000))
    with pytest.raises(RecordingError, match=re.escape(f"{path}: cannot read bag")) as info:
        read_bag(path)
    assert "\n" not in str(info.value)


def test_missing_path_and_empty_directory(tmp_path: Path) -> None:
    with pytest.raises(RecordingError, match="no such bag"):
        read_bag(tmp_path / "nothing.mcap")
    (tmp_path / "empty").mkdir()
    with pytest.raises(RecordingError, match=r"empty: cannot read bag.*metadata"):
        read_bag(tmp_path / "empty")


def test_corrupt_payload_in_valid_container(tmp_path: Path) -> None:
    path = tmp_path / "bad"
    with Writer2(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=typestore(2))
        writer.write(conn, 1, b"\x00\x01\x00\x00\x05")
    with pytest.raises(RecordingError, match=f"{path}: topic /odom"):
        read_bag(path)


@pytest.mark.parametrize(
    ("name", "writer"), [("full.mcap", "bulk"), ("full.mcap", "rosbags"), ("full.bag", "bulk")]
)
def test_write_leaves_no_partial_bag_on_failure(
    tmp_path: Path, recording, monkeypatch, name: str, writer: BagWriter
) -> None:  # type: ignore[no-untyped-def]
    def fail(self):  # type: ignore[no-untyped-def]
        raise OSError(28, os.strerror(28))

    if name.endswith(".bag"):
        monkeypatch.setattr(Writer1, "close", fail)
    elif writer == "rosbags":
        monkeypatch.setattr(Writer2, "close", fail)
    else:
        monkeypatch.setattr(McapWriter, "finish", fail)
    with pytest.raises(RecordingError, match=r"cannot (finish|write) bag.*No space left"):
        write_bag(recording, tmp_path / name, writer=writer)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("drop", ["all", "marvelmind"])
def test_bag_without_embedded_definitions_uses_omnical_types(tmp_path: Path, drop: str) -> None:
    """ROS 2 Humble bags (sqlite3) embed no message definitions; others may embed only some."""
    recording = sample_recording(np.random.default_rng(12), n=5)
    path = tmp_path / "humble"
    store = typestore(2)
    with Writer2(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        for topic in ("/hedge_pos_ang", "/odom"):
            spec, table = TOPICS[topic], recording.topic(topic)
            conn = writer.add_connection(topic, spec.ros2_type, typestore=store)
            for i in range(len(table)):
                writer.write(conn, int(table.t_ns[i]), oracle_bytes(spec, table, i, 2))
    with closing(sqlite3.connect(path / "humble.db3")) as db, db:
        where = "" if drop == "all" else " WHERE topic_type LIKE 'marvelmind%'"
        db.execute(f"DELETE FROM message_definitions{where}")
    back = read_bag(path)
    assert_recordings_equal(
        recording.without(*(set(recording.topics) - {"/hedge_pos_ang", "/odom"})), back
    )


@contextmanager
def _unblocking(fifo: Path) -> Iterator[list[int]]:
    """Watch ``fifo``: each time a reader opens it, open and close its writing end so the
    reader sees an empty file instead of waiting for ever. Yields the list of such opens
    (empty if nobody opened the FIFO), filled until the block ends."""
    opened: list[int] = []
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.01):
            try:  # succeeds only while a reader has it open
                os.close(os.open(fifo, os.O_WRONLY | os.O_NONBLOCK))
            except OSError:
                continue
            opened.append(1)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    try:
        yield opened
    finally:
        done.set()
        thread.join()


def _fifo_bag_folder(folder: Path) -> Path:
    """A ROS 2 bag folder whose metadata.yaml names a storage file that is a FIFO."""
    folder.mkdir()
    (folder / "metadata.yaml").write_text(
        "rosbag2_bagfile_information:\n  version: 5\n  storage_identifier: mcap\n"
        f"  relative_file_paths: [{folder.name}.mcap]\n",
        encoding="utf-8",
    )
    os.mkfifo(folder / f"{folder.name}.mcap")
    return folder / f"{folder.name}.mcap"


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
@pytest.mark.parametrize("read", [read_bag, summarize_bag, BagStream])
@pytest.mark.parametrize("kind", ["fifo.mcap", "fifo.bag", "folder"])
def test_a_fifo_bag_is_refused_before_anyone_opens_it(
    tmp_path: Path, read: Callable[[Path], object], kind: str
) -> None:
    """A FIFO where the bag or its storage file should be: one line naming it, the FIFO never
    opened (it blocked every reader for ever: info, locate, export)."""
    if kind == "folder":
        path, fifo, expected = (
            tmp_path / "run",
            _fifo_bag_folder(tmp_path / "run"),
            "a bag's storage file",
        )
    else:
        path = fifo = tmp_path / kind
        os.mkfifo(fifo)
        expected = "a bag"
    with _unblocking(fifo) as opened, pytest.raises(RecordingError) as info:
        read(path)
    assert str(info.value) == f"{fifo}: is not a regular file (a FIFO), expected {expected}"
    assert opened == []


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs")
def test_recover_passes_over_a_fifo_in_a_bag_folder(tmp_path: Path) -> None:
    """``omnical recover`` of such a folder: nothing to recover, the FIFO never opened (it
    took the folder's only ``*.mcap`` for the storage file and waited on it)."""
    fifo = _fifo_bag_folder(tmp_path / "run")
    fifo.rename(tmp_path / "run" / "other.mcap")  # not the named file: found by its suffix
    with _unblocking(tmp_path / "run" / "other.mcap") as opened:
        with pytest.raises(RecordingError, match="run: no bag file to recover"):
            recover_bag(tmp_path / "run")
        assert not bag_is_complete(tmp_path / "run")
    assert opened == []


def test_a_device_is_not_a_bag() -> None:
    with pytest.raises(RecordingError, match=r"^/dev/null: is not a regular file \(a character"):
        read_bag("/dev/null")
