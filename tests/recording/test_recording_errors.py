"""Which exceptions mean "unreadable bag" and which are omnical's bugs (they must surface)."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from recording_samples import sample_recording
from rosbags.rosbag2 import Writer as Writer2

from omnical.bags import bag as bag_module
from omnical.bags import rawdecode as rawdecode_module
from omnical.bags import recover as recover_module
from omnical.bags.bag import BagWriter, read_bag, write_bag
from omnical.bags.mcapwrite import McapWriter
from omnical.bags.recover import raised_while_parsing, recover_bag
from omnical.errors import RecordingError
from omnical.recording.recording import Recording


@pytest.fixture
def recording() -> Recording:
    return sample_recording(np.random.default_rng(5), n=20)


def _raiser(module: str, error: BaseException) -> Callable[..., Any]:
    """A function that raises ``error`` from a frame that belongs to ``module``."""
    namespace: dict[str, Any] = {"__name__": module, "error": error}
    exec("def raiser(*args, **kwargs):\n    raise error\n", namespace)
    return namespace["raiser"]  # type: ignore[no-any-return]


def _patch_messages(
    monkeypatch: pytest.MonkeyPatch, name: str, module: str, error: BaseException
) -> None:
    """Make the message source of ``read_bag`` raise from inside a rosbags module, as its
    chunk decompression would: omnical's MCAP index reader for an MCAP bag, its chunk reader
    for a ROS 1 bag."""
    source = "channel_messages" if name.endswith(".mcap") else "chunk_messages"
    monkeypatch.setattr(bag_module, source, _raiser(module, error))


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
@pytest.mark.parametrize(
    "error", [KeyError("op"), ValueError("bad record"), IndexError("x"), RuntimeError("LZ4F_x")]
)
def test_a_generic_error_raised_by_rosbags_means_unreadable(
    tmp_path: Path,
    recording: Recording,
    monkeypatch: pytest.MonkeyPatch,
    error: Exception,
    name: str,
) -> None:
    location = write_bag(recording, tmp_path / name)
    _patch_messages(monkeypatch, name, "rosbags.rosbag2.storage_mcap", error)
    with pytest.raises(RecordingError, match=re.escape(f"{location}: cannot read bag")) as info:
        read_bag(location)
    assert type(error).__name__ in str(info.value)


@pytest.mark.parametrize("error", [KeyError("conn"), ValueError("oops"), RuntimeError("bug")])
def test_the_same_error_raised_by_omnical_surfaces(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch, error: Exception
) -> None:
    location = write_bag(recording, tmp_path / "run.mcap")
    monkeypatch.setattr(
        rawdecode_module, "recognise_topic", _raiser("omnical.recording.topics", error)
    )
    with pytest.raises(type(error)) as info:
        read_bag(location)
    assert info.value is error


@pytest.mark.parametrize("name", ["run.mcap", "run.bag"])
def test_an_unexpected_error_class_from_rosbags_surfaces(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch, name: str
) -> None:
    location = write_bag(recording, tmp_path / name)
    _patch_messages(monkeypatch, name, "rosbags.highlevel", TypeError("api"))
    with pytest.raises(TypeError, match="api"):
        read_bag(location)


def test_raised_while_parsing_looks_at_the_innermost_frame() -> None:
    for module, expected in [
        ("rosbags.rosbag1.reader", True),
        ("lz4.frame", True),
        ("omnical.bags.bag", False),
        ("rosbagsx", False),
    ]:
        with pytest.raises(KeyError) as info:
            _raiser(module, KeyError("k"))()
        assert raised_while_parsing(info.value) is expected, module


def test_recover_reports_malformed_records_and_lets_bugs_through(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch
) -> None:
    location = write_bag(recording, tmp_path / "run.bag")
    data = location.read_bytes()
    connection_without_conn = b"\x08\x00\x00\x00" + b"\x04\x00\x00\x00op=\x07" + b"\x00" * 4
    broken = tmp_path / "broken.bag"
    broken.write_bytes(data[:13] + connection_without_conn + data[13:])
    message = f"{broken}: cannot recover bag (record without its 'conn' field)"
    with pytest.raises(RecordingError, match=re.escape(message)):
        recover_bag(broken)
    garbled = tmp_path / "garbled.bag"
    garbled.write_bytes(data[:13] + b"\x08\x00\x00\x00\x04\x00\x00\x00\xff\xfe=\x07" + data[13:])
    with pytest.raises(RecordingError, match=r"cannot recover bag \(UnicodeDecodeError"):
        recover_bag(garbled)
    monkeypatch.setattr(recover_module, "_store", _raiser("omnical.bags.recover", KeyError()))
    with pytest.raises(KeyError):
        recover_bag(location)


@pytest.mark.parametrize("writer", ["bulk", "rosbags"])
def test_a_bug_while_closing_a_bag_surfaces_and_leaves_no_partial_bag(
    tmp_path: Path, recording: Recording, monkeypatch: pytest.MonkeyPatch, writer: BagWriter
) -> None:
    bug = RuntimeError("bug")
    if writer == "bulk":
        monkeypatch.setattr(McapWriter, "finish", _raiser("omnical.bags.mcapwrite", bug))
    else:
        monkeypatch.setattr(Writer2, "close", _raiser("omnical.bags.sink", bug))
    with pytest.raises(RuntimeError, match="bug"):
        write_bag(recording, tmp_path / "run.mcap", writer=writer)
    assert list(tmp_path.iterdir()) == []


def test_an_mcap_cut_inside_its_header_is_unreadable_not_a_bug(
    tmp_path: Path, recording: Recording
) -> None:
    location = write_bag(recording, tmp_path / "run.mcap")
    mcap = next(location.glob("*.mcap"))
    mcap.write_bytes(mcap.read_bytes()[:8])  # the magic alone: rosbags raises a TypeError
    with pytest.raises(RecordingError, match="cannot read bag"):
        read_bag(location)
    for module, expected in [("rosbags.rosbag2.storage_mcap", True), ("rosbags.highlevel", False)]:
        with pytest.raises(TypeError) as info:
            _raiser(module, TypeError("t"))()
        assert raised_while_parsing(info.value) is expected, module


@pytest.mark.parametrize("layout", ["file", "folder"])
def test_an_mcap_of_its_magic_alone_says_so(
    tmp_path: Path, recording: Recording, layout: str
) -> None:
    """Found by a new user: an MCAP file holding its 8-byte magic alone gave "cannot read bag
    (TypeError: ord() expected a character, but string of length 0 found)" and sent them to
    `omnical recover`, which finds nothing. The message now says what is wrong with the file."""
    from omnical.bags.baginfo import summarize_bag

    location = write_bag(recording, tmp_path / "run.mcap")
    mcap = next(location.glob("*.mcap"))
    mcap.write_bytes(b"\x89MCAP0\r\n")
    path = location if layout == "folder" else mcap
    for read in (read_bag, summarize_bag):
        with pytest.raises(RecordingError) as info:
            read(path)
        assert (
            str(info.value)
            == f"{path}: cannot read bag (truncated after the MCAP magic: no records)"
        )
