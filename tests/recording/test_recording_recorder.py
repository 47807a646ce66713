"""BagRecorder (incremental writing) and recover_bag (salvaging an unclosed bag)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from recording_samples import assert_recordings_equal, sample_recording
from rosbags.highlevel import AnyReader

from omnical.bags.bag import read_bag, write_bag
from omnical.bags.recorder import BagRecorder
from omnical.bags.recover import recover_bag
from omnical.errors import RecordingError
from omnical.recording.recording import Recording


def _batches(recording: Recording, parts: int) -> list[tuple[str, dict[str, np.ndarray]]]:
    """Each topic's rows cut into ``parts`` time-ordered batches, interleaving topics."""
    out = []
    for k in range(parts):
        for topic, table in recording.tables.items():
            rows = np.array_split(np.arange(len(table)), parts)[k]
            part = table.take(rows)
            out.append((topic, {"t_ns": part.t_ns, **{n: part[n] for n in part.names}}))
    return out


def _storage(location: Path) -> Path:
    return location / f"{location.name}.mcap" if location.is_dir() else location


@pytest.mark.parametrize("name", ["live.mcap", "live.bag"])
def test_recorder_writes_batches_that_read_back_whole(tmp_path: Path, name: str) -> None:
    recording = sample_recording(np.random.default_rng(21))
    with BagRecorder(tmp_path / name, flush_period_s=0.0) as recorder:
        for topic, columns in _batches(recording, 4):
            recorder.write_rows(topic, **columns)
        assert recorder.message_count == recording.message_count
    assert_recordings_equal(recording, read_bag(recorder.path))
    if name.endswith(".bag"):  # ROS 1 header seq runs on across batches
        with AnyReader([recorder.path]) as reader:
            odom = [c for c in reader.connections if c.topic == "/odom"]
            seqs = [
                reader.deserialize(raw, "nav_msgs/msg/Odometry").header.seq  # type: ignore[attr-defined]
                for _, _, raw in reader.messages(connections=odom)
            ]
        assert seqs == list(range(len(recording.topic("/odom"))))


@pytest.mark.parametrize("name", ["crash.mcap", "crash.bag"])
def test_killed_run_keeps_every_flushed_row(tmp_path: Path, name: str) -> None:
    recording = sample_recording(np.random.default_rng(22))
    batches = _batches(recording, 2)
    half = len(batches) // 2
    snapshot = tmp_path / f"snapshot{Path(name).suffix}"
    recorder = BagRecorder(tmp_path / name, flush_period_s=1e9)
    recorder.open()
    for topic, columns in batches[:half]:
        recorder.write_rows(topic, **columns)
    recorder.flush()
    for topic, columns in batches[half:]:
        recorder.write_rows(topic, **columns)  # still in the writer's memory
    # what the disk holds if the process died now (no index, no footer, no metadata.yaml);
    # it is in the recorder's staging directory, nothing is under the final name yet
    assert recorder.writing_to is not None
    assert not recorder.path.exists()
    shutil.copy(_storage(recorder.writing_to), snapshot)
    recorder.close()
    with pytest.raises(RecordingError, match="omnical recover"):
        read_bag(snapshot)
    salvaged = recover_bag(snapshot)
    assert_recordings_equal(_recording_of(batches[:half]), salvaged)
    # the closed bag holds everything, and recover_bag reads complete bags too
    assert_recordings_equal(recording, read_bag(recorder.path))
    assert_recordings_equal(recording, recover_bag(recorder.path))


def _recording_of(batches: list[tuple[str, dict[str, np.ndarray]]]) -> Recording:
    from omnical.recording.recording import RecordingBuilder

    builder = RecordingBuilder()
    for topic, columns in batches:
        builder.add_many(topic, **columns)
    return builder.build()


def test_exception_inside_with_block_still_closes_the_bag(tmp_path: Path) -> None:
    recording = sample_recording(np.random.default_rng(23))
    with pytest.raises(KeyboardInterrupt), BagRecorder(tmp_path / "stopped.mcap") as recorder:
        for topic, columns in _batches(recording, 1):
            recorder.write_rows(topic, **columns)
        raise KeyboardInterrupt
    # kept complete, under a name that says the run was cut short
    assert recorder.kept_at == tmp_path / "stopped.partial"
    assert not (tmp_path / "stopped").exists()
    assert_recordings_equal(recording, read_bag(tmp_path / "stopped.partial"))


def test_recorder_guards(tmp_path: Path) -> None:
    write_bag(sample_recording(np.random.default_rng(24), n=3), tmp_path / "old.mcap")
    with pytest.raises(RecordingError, match="already exists"):
        BagRecorder(tmp_path / "old.mcap").open()
    recorder = BagRecorder(tmp_path / "new.mcap")
    with pytest.raises(RecordingError, match="not open"):
        recorder.write_rows("/cmd_vel", [1], vx_mps=[0.0], vy_mps=[0.0], wz_radps=[0.0])
    with recorder, pytest.raises(RecordingError, match="cannot write topic /wheels"):
        recorder.write_rows("/wheels", [1], w1_radps=[0.0])
    with BagRecorder(tmp_path / "old.mcap", overwrite=True) as again:
        again.write_rows("/cmd_vel", [7], vx_mps=[1.0], vy_mps=[0.0], wz_radps=[0.0])
    assert read_bag(tmp_path / "old").topics == ("/cmd_vel",)


def test_recover_rejects_non_bags(tmp_path: Path) -> None:
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"hello world, not a bag at all")
    with pytest.raises(RecordingError, match="neither an MCAP nor a ROS 1"):
        recover_bag(junk)
    with pytest.raises(RecordingError, match="no bag file"):
        recover_bag(tmp_path / "missing")


@pytest.mark.parametrize("name", ["full.mcap", "full.bag"])
def test_a_full_disk_at_close_names_the_staging_and_recover(
    tmp_path: Path, name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The disk full while the index is written, and again in the writer's abort: one
    RecordingError naming where the flushed chunks are and the command that salvages them
    (the abort's second ENOSPC had replaced it), and those chunks recover."""
    import errno
    import os

    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    recording = sample_recording(np.random.default_rng(24))
    batches = _batches(recording, 2)

    def full(self: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    recorder = BagRecorder(tmp_path / name, flush_period_s=0.0)
    recorder.open()
    for topic, columns in batches:
        recorder.write_rows(topic, **columns)
    staging = recorder.writing_to
    assert staging is not None
    for writer in (Writer1, Writer2):
        monkeypatch.setattr(writer, "close", full)
        monkeypatch.setattr(writer, "abort", full, raising=False)
    with pytest.raises(RecordingError) as info:
        recorder.close()
    message = str(info.value)
    assert "cannot finish bag" in message and "No space left on device" in message
    assert f"kept in {staging.parent}" in message
    assert f"omnical recover {recorder.path}" in message
    monkeypatch.undo()
    assert_recordings_equal(recording, recover_bag(staging))
