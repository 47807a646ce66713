"""Compressed bags by default, selective streaming reads, and ``info`` from the bag's index."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from recording_samples import assert_recordings_equal, sample_recording
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

from omnical.bags.bag import BagStream, indexed_mcap, read_bag, write_bag
from omnical.bags.baginfo import summarize_bag
from omnical.bags.mcapindex import read_summary
from omnical.bags.recorder import BagRecorder
from omnical.bags.recover import recover_bag
from omnical.bags.typestores import typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording
from omnical.recording.summary import summarize


@pytest.fixture(scope="module")
def recording() -> Recording:
    return sample_recording(np.random.default_rng(31), n=300)


def _mcap(location: Path) -> Path:
    return location / f"{location.name}.mcap"


def _ros1_compressions(path: Path) -> set[bytes]:
    data = path.read_bytes()
    return {c for c in (b"none", b"lz4", b"bz2") if b"compression=" + c in data}


@pytest.mark.parametrize(
    ("name", "compression", "expected"),
    [
        ("run.mcap", "auto", "zstd"),
        ("run.mcap", "zstd", "zstd"),
        ("run.mcap", None, ""),
        ("run.bag", "auto", "lz4"),
        ("run.bag", "bz2", "bz2"),
        ("run.bag", None, "none"),
    ],
)
def test_compression_round_trips_on_every_reader_path(
    tmp_path: Path, recording: Recording, name: str, compression: str | None, expected: str
) -> None:
    location = write_bag(recording, tmp_path / name, compression=compression)  # type: ignore[arg-type]
    if location.is_dir():
        summary = read_summary(_mcap(location))
        assert summary is not None
        assert {c.compression for c in summary.chunks} == {expected}
        meta = yaml.safe_load((location / "metadata.yaml").read_text())[
            "rosbag2_bagfile_information"
        ]
        # rosbag2: compression_* describe rosbag2's own file/message compression; MCAP chunk
        # compression is the storage's business and leaves both empty.
        assert meta["compression_format"] == "" and meta["compression_mode"] == ""
        assert meta["relative_file_paths"] == [f"{location.name}.mcap"]
    else:
        assert _ros1_compressions(location) == {expected.encode()}
    with AnyReader([location]) as reader:
        assert sum(1 for _ in reader.messages()) == recording.message_count
    assert_recordings_equal(recording, read_bag(location))
    assert_recordings_equal(recording, recover_bag(location))
    assert summarize_bag(location) == summarize(recording)


def test_default_bags_are_smaller(tmp_path: Path, recording: Recording) -> None:
    smooth = recording.with_table("/odom", recording.topic("/odom").take(np.arange(300)))
    packed = write_bag(smooth, tmp_path / "z.mcap")
    plain = write_bag(smooth, tmp_path / "u.mcap", compression=None)
    assert _mcap(packed).stat().st_size < _mcap(plain).stat().st_size


@pytest.mark.parametrize(("name", "bad"), [("run.mcap", "lz4"), ("run.bag", "zstd"), ("x", "gz")])
def test_compression_that_does_not_suit_the_format_is_refused(
    tmp_path: Path, recording: Recording, name: str, bad: str
) -> None:
    with pytest.raises(RecordingError, match="chunk compression"):
        write_bag(recording, tmp_path / name, compression=bad)  # type: ignore[arg-type]
    with pytest.raises(RecordingError, match="chunk compression"):
        BagRecorder(tmp_path / name, compression=bad)  # type: ignore[arg-type]
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("name", ["live.mcap", "live.bag"])
def test_killed_compressed_recording_is_recovered(
    tmp_path: Path, recording: Recording, name: str
) -> None:
    recorder = BagRecorder(tmp_path / name, flush_period_s=0.0)
    recorder.open()
    for topic, table in recording.tables.items():
        recorder.write_rows(topic, table.t_ns, **{c: table[c] for c in table.names})
    recorder.flush()
    sink = recorder._sink
    assert sink is not None
    sink.abort()  # what kill -9 leaves: flushed compressed chunks, no index
    assert recorder.writing_to is None or not recorder.path.exists()
    assert_recordings_equal(recording, recover_bag(sink.location))


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
def test_selective_read_equals_the_full_read(
    tmp_path: Path, recording: Recording, name: str
) -> None:
    location = write_bag(recording, tmp_path / name)
    full = read_bag(location)
    wanted = ("/odom", "/beacon_raw_distance", "/omnical/events")
    part = read_bag(location, wanted)
    assert part.topics == tuple(t for t in full.topics if t in wanted)
    assert_recordings_equal(full.without(*(t for t in full.topics if t not in wanted)), part)
    assert read_bag(location, ()).topics == ()
    # a topic name that is not there: the bag's own topics are listed (issue 29: they were
    # omnical's names, which tell a user with a typo in --wheel-topic nothing)
    with pytest.raises(RecordingError, match=r"no topic /nope .* the bag has: /beacon_raw_"):
        read_bag(location, ["/nope"])


def test_bare_mcap_file_and_uncompressed_bag_use_the_index(
    tmp_path: Path, recording: Recording
) -> None:
    location = write_bag(recording, tmp_path / "run.mcap", compression=None)
    bare = tmp_path / "copy.mcap"
    shutil.copy(_mcap(location), bare)
    assert indexed_mcap(location) is not None and indexed_mcap(bare) is not None
    assert_recordings_equal(recording, read_bag(bare, None))
    assert summarize_bag(bare) == summarize(recording)


def test_small_decode_batches_give_the_same_tables(recording: Recording, tmp_path: Path) -> None:
    location = write_bag(recording, tmp_path / "run.mcap")
    stream = BagStream(location, batch=7, whole=True)
    tables = {part.topic: part.table for part in stream.parts()}
    assert_recordings_equal(recording, Recording(tables, stream.skipped, stream.notes))


def test_info_of_a_third_party_bag_lists_skipped_topics(tmp_path: Path) -> None:
    store = typestore(2)
    path = tmp_path / "theirs"
    with Writer2(path, version=8, storage_plugin=StoragePlugin.MCAP) as writer:
        chat = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=store)
        odom = writer.add_connection("odom", "nav_msgs/msg/Odometry", typestore=store)
        msg = store.types["std_msgs/msg/String"](data="hi")
        writer.write(chat, 5, store.serialize_cdr(msg, "std_msgs/msg/String"))
        odom_msg = store.types["nav_msgs/msg/Odometry"]
        header = store.types["std_msgs/msg/Header"]
        time = store.types["builtin_interfaces/msg/Time"]
        pose = store.types["geometry_msgs/msg/PoseWithCovariance"]
        twist = store.types["geometry_msgs/msg/TwistWithCovariance"]
        point = store.types["geometry_msgs/msg/Point"]
        quat = store.types["geometry_msgs/msg/Quaternion"]
        vec = store.types["geometry_msgs/msg/Vector3"]
        for k in range(4):
            message = odom_msg(
                header=header(stamp=time(sec=0, nanosec=0), frame_id="odom"),
                child_frame_id="base_link",
                pose=pose(
                    pose=store.types["geometry_msgs/msg/Pose"](
                        position=point(x=float(k), y=0.0, z=0.0),
                        orientation=quat(x=0.0, y=0.0, z=0.0, w=1.0),
                    ),
                    covariance=np.zeros(36),
                ),
                twist=twist(
                    twist=store.types["geometry_msgs/msg/Twist"](
                        linear=vec(x=0.0, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=0.0)
                    ),
                    covariance=np.zeros(36),
                ),
            )
            writer.write(odom, 10 + k, store.serialize_cdr(message, "nav_msgs/msg/Odometry"))
    got = summarize_bag(path)
    assert got == summarize(read_bag(path))
    assert dict(got.skipped_topics) == {"/chatter": "std_msgs/msg/String"}
    assert got.distance_odom_m == pytest.approx(3.0)
    assert [t.count for t in got.topics] == [4]
