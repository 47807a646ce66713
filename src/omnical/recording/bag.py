"""Read and write recordings as ROS bags: ROS 2 with MCAP storage by default, ROS 1 too.

On-disk rule (what ``--out`` means):

* ``RUN.bag`` → a ROS 1 bag file ``RUN.bag``.
* ``RUN.mcap`` or ``RUN`` → a ROS 2 bag **directory** ``RUN/`` holding ``metadata.yaml`` and
  ``RUN.mcap`` (rosbags names the storage file after the directory). This is the layout
  ``ros2 bag record -o RUN -s mcap`` makes, so ``ros2 bag info RUN`` and
  ``rosbags.highlevel.AnyReader([Path("RUN")])`` both open it; the inner ``RUN/RUN.mcap`` is
  also a complete standalone MCAP file (it embeds the same rosbag2 metadata) that AnyReader,
  Foxglove and ``ros2 bag info RUN/RUN.mcap`` (Iron or newer) open on their own.

:func:`bag_location` applies the rule; the CLI prints its result. :func:`read_bag` accepts a
bag directory, a ``.bag`` file, a bare ``.mcap`` (or ``.db3``) file, and also the path that was
given to :func:`write_bag` (``RUN.mcap`` when only ``RUN/`` exists).

Writing goes to a temporary sibling first and is moved into place when complete, so a failed
write never leaves half a bag and never destroys the previous one. An existing bag is only
replaced with ``overwrite=True``, and a directory that does not look like a ROS 2 bag is never
replaced.
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Collection
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from omnical.errors import RecordingError
from omnical.recording.mcapindex import McapIndexError, McapSummary, channel_messages, read_summary
from omnical.recording.rawdecode import StreamDecoder
from omnical.recording.recording import Recording
from omnical.recording.recover import (
    PARSING_ERRORS,
    UNREADABLE_BAG_ERRORS,
    has_bag_magic,
    raised_while_parsing,
)
from omnical.recording.sink import (
    DEFAULT_COMPRESSION,
    BagCompression,
    BagSink,
    chunk_compression,
    encode_topic,
    topic_spec,
)
from omnical.recording.topics import TOPICS, recognise_topic
from omnical.recording.typestores import RosVersion, complete_store, typestore

__all__ = ["bag_location", "bag_ros_version", "indexed_mcap", "read_bag", "write_bag"]

_BAG_DIR_FILES = {".mcap", ".db3", ".yaml", ".zstd"}


def bag_location(path: str | Path) -> Path:
    """Where a bag written to ``path`` lives: ``X.bag`` → file, ``X.mcap`` or ``X`` → dir ``X``."""
    p = Path(path)
    return p.with_suffix("") if p.suffix == ".mcap" else p


def bag_ros_version(path: str | Path) -> RosVersion:
    """1 for a ``.bag`` path, else 2."""
    return 1 if Path(path).suffix == ".bag" else 2


def _is_bag_dir(path: Path) -> bool:
    entries = list(path.iterdir())
    return bool(entries) and all(e.is_file() and e.suffix in _BAG_DIR_FILES for e in entries)


def check_target(target: Path, *, overwrite: bool) -> None:
    """Refuse to write over ``target`` unless allowed and it is a bag of the expected kind."""
    if not target.exists() and not target.is_symlink():
        return
    if not overwrite:
        msg = f"{target}: already exists; pass overwrite=True to replace it"
        raise RecordingError(msg)
    if bag_ros_version(target) == 2 and not (target.is_dir() and _is_bag_dir(target)):
        msg = f"{target}: exists and is not a ROS 2 bag directory; refusing to replace it"
        raise RecordingError(msg)
    if bag_ros_version(target) == 1 and not target.is_file():
        msg = f"{target}: exists and is not a ROS 1 bag file; refusing to replace it"
        raise RecordingError(msg)


def remove_bag(target: Path) -> None:
    """Delete a bag that :func:`check_target` accepted for replacement."""
    if target.is_dir():
        shutil.rmtree(target)
    elif target.exists() or target.is_symlink():
        target.unlink()


def write_bag(
    recording: Recording,
    path: str | Path,
    *,
    overwrite: bool = False,
    compression: BagCompression | None = DEFAULT_COMPRESSION,
) -> Path:
    """Write ``recording`` as a bag at ``bag_location(path)`` and return that location.

    Messages are written in global time order (ties keep topic order). Topics without rows
    are not written. Every topic must be canonical (:data:`omnical.recording.topics.TOPICS`).

    Args:
        recording: What to write.
        path: Where (the :func:`bag_location` rule applies).
        overwrite: Replace an existing bag at the location.
        compression: Chunk compression: ``"auto"`` (zstd MCAP chunks for ROS 2, lz4 chunks for
            ROS 1), ``"zstd"`` (ROS 2), ``"lz4"`` or ``"bz2"`` (ROS 1), or None for an
            uncompressed bag.

    Raises:
        RecordingError: The target exists (and ``overwrite`` is False, or it is not a bag),
            a topic is not canonical, a time is negative, the compression does not suit the
            bag format, or the file system refuses.
    """
    target = bag_location(path)
    ros = bag_ros_version(target)
    chunk_compression(compression, ros, target)
    check_target(target, overwrite=overwrite)
    for topic in recording.tables:
        topic_spec(topic, target)
    topics: list[str] = []
    times: list[int] = []
    payloads: list[memoryview] = []
    for topic, table in recording.tables.items():
        if len(table):
            payloads.extend(encode_topic(topic, table, ros, target))
            times.extend(table.t_ns.tolist())
            topics.extend([topic] * len(table))
    order = np.argsort(np.asarray(times, dtype=np.int64), kind="stable").tolist()
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    except OSError as err:
        msg = f"{target}: cannot create bag: {err.strerror}"
        raise RecordingError(msg) from None
    try:
        sink = BagSink(staging / target.name, ros, compression)
        sink.open()
        try:
            sink.write_messages(
                [topics[i] for i in order], [times[i] for i in order], [payloads[i] for i in order]
            )
            sink.close()
        except BaseException:
            sink.abort()
            raise
        if target.exists() or target.is_symlink():
            target.rename(staging / ".replaced")
        (staging / target.name).rename(target)
    except RecordingError:
        raise
    except OSError as err:
        msg = f"{target}: cannot write bag: {err}"
        raise RecordingError(msg) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def resolve_source(path: str | Path) -> Path:
    """The bag to read for ``path``, applying the :func:`bag_location` rule if needed."""
    p = Path(path)
    if p.exists():
        return p
    alt = bag_location(p)
    if alt != p and (alt / "metadata.yaml").is_file():
        return alt
    msg = f"{p}: no such bag"
    raise RecordingError(msg)


def _unreadable(source: Path, err: Exception) -> RecordingError:
    """The one-line error of a bag rosbags cannot read, with the first line of its reason."""
    reason = (str(err).splitlines() or [type(err).__name__])[0]
    msg = f"{source}: cannot read bag ({type(err).__name__}: {reason})"
    if has_bag_magic(source):
        msg += "; if its recording was interrupted, recover_bag() salvages what was flushed"
    return RecordingError(msg)


def read_bag(path: str | Path, topics: Collection[str] | None = None) -> Recording:
    """Read the topics omnical knows from a ROS 1 or ROS 2 bag (only ``topics`` if given).

    Marvelmind topics are recognised by message type whatever their name; ``/cmd_vel``
    (Twist or TwistStamped), ``/odom``, ``/imu``, ``/ground_truth`` and ``/omnical/events``
    by name. Other topics are listed in ``Recording.skipped_topics``. Row times are bag times.

    Reading streams: messages are decoded a batch at a time (:class:`StreamDecoder`), so
    memory holds the decoded tables of the topics asked for, not the bag. An indexed MCAP
    file (what omnical, rosbags and ``ros2 bag record -s mcap`` write) is read through its
    chunk and message indexes (:mod:`omnical.recording.mcapindex`): only chunks holding a
    wanted topic are inflated, and only wanted messages are touched. Other bags (ROS 1,
    SQLite, unindexed MCAP) go through rosbags' ``AnyReader`` with a connection filter.

    Args:
        path: The bag (see :func:`resolve_source`).
        topics: Canonical topic names to read (:data:`omnical.recording.topics.TOPICS`);
            None reads every recognised topic. Topics the bag lacks are simply absent.

    Raises:
        RecordingError: Missing path, not a bag, truncated or corrupt bag, undecodable message,
            unknown topic name; the message is one line naming the file.
    """
    source = resolve_source(path)
    if topics is not None and (unknown := sorted(set(topics) - set(TOPICS))):
        msg = f"{source}: unknown topics {', '.join(unknown)} (topics: {', '.join(TOPICS)})"
        raise RecordingError(msg)
    ros: RosVersion = 1 if source.suffix == ".bag" else 2
    if ros == 1 and source.is_file() and not has_bag_magic(source):
        msg = f"{source}: cannot read bag (not a ROS 1 bag: no '#ROSBAG V2.0' header)"
        raise RecordingError(msg)
    try:
        with AnyReader([source], default_typestore=typestore(ros)) as reader:
            store = reader.typestore
            complete_store(store, [c.msgtype for c in reader.connections], ros)
            decoder = StreamDecoder(store, ros, str(source), topics, recognise=recognise_topic)
            summary = indexed_mcap(source, reader)
            if summary is not None:
                _read_indexed(summary, decoder)
            else:
                _read_any(reader, decoder)
    except McapIndexError as err:
        raise _unreadable(source, err) from None
    except UNREADABLE_BAG_ERRORS as err:
        raise _unreadable(source, err) from None
    except PARSING_ERRORS as err:
        if not raised_while_parsing(err):
            raise  # omnical's own bug: keep the traceback
        raise _unreadable(source, err) from None
    return decoder.recording()


def _read_any(reader: AnyReader, decoder: StreamDecoder) -> None:
    """Messages of the wanted connections through rosbags, one by one."""
    handles: dict[tuple[int, int], int] = {}
    wanted = []
    for conn in reader.connections:
        handle = decoder.add_connection(conn.topic, conn.msgtype)
        if handle is not None:
            handles[(id(conn.owner), conn.id)] = handle
            wanted.append(conn)
    if wanted:
        add = decoder.add
        for conn, t_ns, payload in reader.messages(connections=wanted):
            add(handles[(id(conn.owner), conn.id)], t_ns, payload)


def _read_indexed(summary: McapSummary, decoder: StreamDecoder) -> None:
    """Messages of the wanted channels of an indexed MCAP file, chunk by chunk."""
    handles: dict[int, int] = {}
    for cid, channel in sorted(summary.channels.items()):
        handle = decoder.add_connection(channel.topic, channel.msgtype)
        if handle is not None:
            handles[cid] = handle
    if handles:
        for cid, t_ns, payloads in channel_messages(summary, handles):
            decoder.extend(handles[cid], t_ns, payloads)


def canonical_topic(topic: str, msgtype: str) -> str | None:
    """The canonical topic a bag connection is read as, or None (see :func:`read_bag`)."""
    hit = recognise_topic(topic, msgtype)
    return None if hit is None else hit[0]


def indexed_mcap(source: Path, reader: AnyReader | None = None) -> McapSummary | None:
    """The MCAP summary of a one-file ROS 2 bag whose storage compresses at most its chunks.

    None for anything else (ROS 1, SQLite, split bags, rosbag2 file or message compression,
    an MCAP file without summary, chunk indexes or statistics): read those with rosbags.

    Raises:
        McapIndexError: The MCAP summary is malformed.
        OSError: The file cannot be read.
    """
    if source.suffix == ".bag":
        return None
    if source.is_dir():
        files = sorted(p for p in source.iterdir() if p.suffix in {".mcap", ".db3", ".zstd"})
        if len(files) != 1 or files[0].suffix != ".mcap" or _rosbag2_compression(reader):
            return None
        file = files[0]
    elif source.suffix == ".mcap":
        file = source
    else:
        return None
    return read_summary(file)


def _rosbag2_compression(reader: AnyReader | None) -> bool:
    """Whether ``metadata.yaml`` declares rosbag2 file or message compression."""
    if reader is None:
        return False
    return any(bool(getattr(r, "compression_mode", None)) for r in reader.readers)
