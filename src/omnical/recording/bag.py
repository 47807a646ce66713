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
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader

from omnical.errors import RecordingError
from omnical.recording.rawdecode import RawConnection, recording_from_connections
from omnical.recording.recording import Recording
from omnical.recording.recover import (
    PARSING_ERRORS,
    UNREADABLE_BAG_ERRORS,
    has_bag_magic,
    raised_while_parsing,
)
from omnical.recording.sink import BagSink, encode_topic, topic_spec
from omnical.recording.topics import recognise_topic
from omnical.recording.typestores import RosVersion, complete_store, typestore

__all__ = ["bag_location", "bag_ros_version", "read_bag", "write_bag"]

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


def write_bag(recording: Recording, path: str | Path, *, overwrite: bool = False) -> Path:
    """Write ``recording`` as a bag at ``bag_location(path)`` and return that location.

    Messages are written in global time order (ties keep topic order). Topics without rows
    are not written. Every topic must be canonical (:data:`omnical.recording.topics.TOPICS`).

    Raises:
        RecordingError: The target exists (and ``overwrite`` is False, or it is not a bag),
            a topic is not canonical, a time is negative, or the file system refuses.
    """
    target = bag_location(path)
    ros = bag_ros_version(target)
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
        sink = BagSink(staging / target.name, ros)
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


def read_bag(path: str | Path) -> Recording:
    """Read the topics omnical knows from a ROS 1 or ROS 2 bag.

    Marvelmind topics are recognised by message type whatever their name; ``/cmd_vel``
    (Twist or TwistStamped), ``/odom``, ``/imu``, ``/ground_truth`` and ``/omnical/events``
    by name. Other topics are listed in ``Recording.skipped_topics``. Row times are bag times.

    Raises:
        RecordingError: Missing path, not a bag, truncated or corrupt bag, undecodable message;
            the message is one line naming the file.
    """
    source = resolve_source(path)
    ros: RosVersion = 1 if source.suffix == ".bag" else 2
    if ros == 1 and source.is_file() and not has_bag_magic(source):
        msg = f"{source}: cannot read bag (not a ROS 1 bag: no '#ROSBAG V2.0' header)"
        raise RecordingError(msg)
    raw: dict[tuple[int, int], RawConnection] = {}
    order: list[RawConnection] = []
    try:
        with AnyReader([source], default_typestore=typestore(ros)) as reader:
            store = reader.typestore
            wanted = []
            for conn in reader.connections:
                rc = RawConnection(conn.topic, conn.msgtype)
                order.append(rc)
                if recognise_topic(conn.topic, conn.msgtype) is not None:
                    raw[(id(conn.owner), conn.id)] = rc
                    wanted.append(conn)
            if wanted:
                for conn, t_ns, payload in reader.messages(connections=wanted):
                    rc = raw[(id(conn.owner), conn.id)]
                    rc.times_ns.append(t_ns)
                    rc.payloads.append(payload)
    except UNREADABLE_BAG_ERRORS as err:
        raise _unreadable(source, err) from None
    except PARSING_ERRORS as err:
        if not raised_while_parsing(err):
            raise  # omnical's own bug: keep the traceback
        raise _unreadable(source, err) from None
    complete_store(store, [rc.msgtype for rc in raw.values()], ros)
    return recording_from_connections(order, store, ros, str(source))
