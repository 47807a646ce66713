"""Read and write recordings as ROS bags: ROS 2 with MCAP storage by default, ROS 1 too.

``RUN.bag`` is ROS 1, ``RUN.mcap`` or ``RUN`` a ROS 2 directory ``RUN/`` (:func:`bag_location`).
:func:`write_bag` stages, then swaps in whole, replacing only omnical's bags; :func:`read_bag` any.
"""

from __future__ import annotations

import shutil
import stat
import tempfile
from collections.abc import Callable, Collection, Iterable, Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import Any, Final, Literal

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import Connection
from rosbags.rosbag1 import Reader as Ros1Reader

from omnical.bags.mcapindex import (
    MCAP_MAGIC,
    McapIndexError,
    McapSummary,
    channel_messages,
    read_summary,
)
from omnical.bags.rawdecode import DECODE_BATCH, Decoder, Part
from omnical.bags.recover import (
    PARSING_ERRORS,
    UNREADABLE_BAG_ERRORS,
    bag_is_complete,
    has_bag_magic,
    raised_while_parsing,
    storage_file,
)
from omnical.bags.ros1chunks import LeanRos1Reader, Ros1ChunkError, chunk_messages
from omnical.bags.sink import (
    DEFAULT_COMPRESSION,
    OMNICAL_CALLERID,
    OMNICAL_MARKER,
    OMNICAL_MARKER_KEY,
    BagCompression,
    BagSink,
    checked_spec,
    chunk_compression,
    encode_topic,
    write_ros2_bag,
)
from omnical.bags.staging import (
    free_name,
    held_stops,
    inside_open_staging,
    make_staging,
    renamed_in_message,
    swap_into_place,
    sweep_staging,
)
from omnical.bags.typestores import RosVersion, complete_store, typestore
from omnical.errors import ConfigError, OmnicalError, RecordingError
from omnical.recording.recording import Recording
from omnical.recording.summary import TRAVEL_KEY_PREFIX, TravelTally
from omnical.recording.topics import GROUND_TRUTH, ODOM, TOPICS, MessageKind, recognise_topic
from omnical.userfiles import file_kind, parse_yaml

__all__ = [
    "STREAM_BATCH",
    "BagStream",
    "BagWriter",
    "bag_location",
    "bag_ros_version",
    "bag_source",
    "check_bag_output",
    "check_target",
    "check_topics",
    "connection_types",
    "foreign_bag_reason",
    "indexed_mcap",
    "partial_location",
    "put_in_place",
    "read_bag",
    "reading_bag",
    "ros2_bag_files",
    "unreadable",
    "write_bag",
]

_METADATA = "metadata.yaml"
_METADATA_MAX_BYTES = 1 << 20


def bag_location(path: str | Path) -> Path:
    """Where a bag written to ``path`` lives: ``X.bag`` → file, ``X.mcap`` or ``X`` → dir ``X``."""
    p = Path(path)
    return p.with_suffix("") if p.suffix == ".mcap" else p


def bag_ros_version(path: str | Path) -> RosVersion:
    """1 for a ``.bag`` path, else 2."""
    return 1 if Path(path).suffix == ".bag" else 2


def ros2_bag_files(target: Path) -> tuple[list[str], dict[str, object]]:
    """The files a ROS 2 bag directory consists of, and its rosbag2 metadata.

    Raises:
        RecordingError: No readable ``metadata.yaml``, or one that is not rosbag2's.
    """
    meta = target / _METADATA
    try:
        if not meta.is_file() or meta.is_symlink():
            msg = "no metadata.yaml"
            raise RecordingError(msg)
        if meta.stat().st_size > _METADATA_MAX_BYTES:
            msg = "metadata.yaml larger than 1 MiB"
            raise RecordingError(msg)
        loaded = parse_yaml(meta.read_text(encoding="utf-8"), str(meta), "rosbag2 metadata")
    except ConfigError as err:  # an alias, too deep, too many values, not YAML
        msg = f"unreadable metadata.yaml ({err})"
        raise RecordingError(msg) from None
    except (OSError, UnicodeDecodeError) as err:
        if isinstance(err, RecordingError):
            raise
        msg = f"unreadable metadata.yaml ({type(err).__name__})"
        raise RecordingError(msg) from None
    info = loaded.get("rosbag2_bagfile_information") if isinstance(loaded, dict) else None
    files = info.get("relative_file_paths") if isinstance(info, dict) else None
    if not isinstance(info, dict) or not isinstance(files, list) or not files:
        msg = "metadata.yaml is not a rosbag2 bag's"
        raise RecordingError(msg)
    names = [f for f in files if isinstance(f, str) and f and Path(f).name == f]
    if len(names) != len(files):
        msg = "metadata.yaml lists storage files outside its directory"
        raise RecordingError(msg)
    return names, info


def foreign_bag_reason(target: Path) -> str | None:
    """Why ``target`` is not a complete bag omnical wrote (None if it is one).

    Checked: the marker (ROS 2 ``custom_data: {omnical.writer: omnical}``, ROS 1 caller id
    ``/omnical``) and the structure (exactly ``metadata.yaml`` and its MCAP files; an indexed
    ROS 1 file). A foreign bag, even a valid one, is not omnical's.
    """
    if target.is_symlink():
        return "it is a symbolic link"
    if bag_ros_version(target) == 2:
        if not target.is_dir():
            return "it is not a directory"
        try:
            names, info = ros2_bag_files(target)
        except RecordingError as err:
            return str(err)
        try:
            present = {e.name for e in target.iterdir()}
        except OSError as err:
            return f"cannot list it ({err.strerror})"
        if others := sorted(present - {_METADATA, *names}):
            return f"it holds files that are not part of the bag ({', '.join(others[:3])})"
        if missing := sorted(set(names) - present):
            return f"storage file {missing[0]} is missing"
        if not all(has_bag_magic(target / n) for n in names):
            return "its storage file is not an MCAP file"
        custom = info.get("custom_data")
        if not isinstance(custom, dict) or custom.get(OMNICAL_MARKER_KEY) != OMNICAL_MARKER:
            return "it is a ROS 2 bag omnical did not write (no omnical marker)"
        return None
    if not target.is_file():
        return "it is not a file"
    if not has_bag_magic(target):
        return "it is not a ROS 1 bag"
    try:
        with Ros1Reader(target) as reader:
            callers = {getattr(c.ext, "callerid", None) for c in reader.connections}
    except (*UNREADABLE_BAG_ERRORS, *PARSING_ERRORS) as err:
        return f"it is not a complete ROS 1 bag ({type(err).__name__})"
    if callers - {OMNICAL_CALLERID}:
        return "it is a ROS 1 bag omnical did not write (no omnical caller id)"
    return None


def check_target(target: Path, *, overwrite: bool) -> None:
    """Refuse to write over ``target`` unless allowed and it is a bag omnical wrote.

    Raises:
        RecordingError: ``target`` exists and ``overwrite`` is False, or it is anything but a
            complete bag omnical wrote (:func:`foreign_bag_reason`; a symbolic link, a
            device). Only a regular file's first bytes are read.
    """
    try:
        mode = target.lstat().st_mode
    except FileNotFoundError:
        return
    except OSError as err:
        msg = f"{target}: cannot check it: {err.strerror or err}"
        raise RecordingError(msg) from None
    if stat.S_ISLNK(mode):
        msg = f"{target}: is a symbolic link; omnical does not write through links — give the bag's own name"
        raise RecordingError(msg)
    if not (stat.S_ISREG(mode) or stat.S_ISDIR(mode)):
        msg = f"{target}: is a device, pipe or socket, not a bag; give a new file name"
        raise RecordingError(msg)
    if not overwrite:
        msg = f"{target}: already exists; add --overwrite to replace it"
        raise RecordingError(msg)
    if (reason := foreign_bag_reason(target)) is not None:
        msg = f"{target}: exists and is not a bag omnical wrote ({reason}); refusing to replace it"
        raise RecordingError(msg)


def check_bag_output(path: str | Path, *, overwrite: bool) -> Path:
    """Check, before any work, that a bag can be written at ``bag_location(path)``.

    The target must pass :func:`check_target` and the place be writable (a staging directory
    is made and removed); stale stagings are swept (:func:`~omnical.bags.staging.sweep_staging`).

    Returns:
        The bag's location.

    Raises:
        RecordingError: One line naming the path and the reason.
    """
    target = bag_location(path)
    check_target(target, overwrite=overwrite)
    parent = target.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        msg = f"{target}: cannot create bag: {parent} is not a directory"
        raise RecordingError(msg)
    try:
        Path(tempfile.mkdtemp(prefix=f".{target.name}.omnical-probe-", dir=parent)).rmdir()
    except OSError as err:
        msg = f"{target}: cannot create bag: {parent} is not writable ({err.strerror or err})"
        raise RecordingError(msg) from None
    sweep_staging(target)
    return target


def partial_location(target: Path, label: str = "partial") -> Path:
    """A free name saying "partial" for an interrupted run of ``target``, never an existing one.

    ``RUN`` (ROS 2 directory) → ``RUN.partial``, then ``RUN.partial-2``, ...; ``RUN.bag`` →
    ``RUN.partial.bag``, ``RUN.partial-2.bag``, ... (``label`` replaces ``partial``).
    """
    try:
        return free_name(target, label, ".bag" if bag_ros_version(target) == 1 else "")
    except OmnicalError as err:
        raise RecordingError(str(err)) from None


BagWriter = Literal["bulk", "rosbags"]
"""How :func:`write_bag` writes a ROS 2 bag: ``bulk`` (:func:`~omnical.bags.sink.write_ros2_bag`)
or ``rosbags`` (message by message, ``bench/bench_bag.py``'s baseline). ROS 1: always rosbags."""


def write_bag(
    recording: Recording,
    path: str | Path,
    *,
    overwrite: bool = False,
    compression: BagCompression | None = DEFAULT_COMPRESSION,
    writer: BagWriter = "bulk",
    divert: Callable[[], bool] | None = None,
) -> Path:
    """Write ``recording`` as a bag at ``bag_location(path)`` and return where it went.

    Messages go in global time order (ties keep topic order); topics without rows are left
    out; every topic must be canonical. The bag is staged and swapped in whole, or kept under
    a free ``.partial`` name (the earlier bag stays) if a stop signal or ``divert()`` says so.

    Args:
        recording: What to write.
        path: Where (the :func:`bag_location` rule applies).
        overwrite: Replace an existing bag at the location, if omnical wrote it
            (:func:`foreign_bag_reason`); anything else there is never replaced.
        compression: Chunk compression: ``"auto"`` (zstd MCAP chunks for ROS 2, lz4 chunks for
            ROS 1), ``"zstd"`` (ROS 2), ``"lz4"`` or ``"bz2"`` (ROS 1), or None for an
            uncompressed bag.
        writer: How a ROS 2 bag is written (:data:`BagWriter`); the bags read the same.
        divert: Asked when the bag is complete: True keeps it under a ``.partial`` name
            (a stop signal the caller noted while it was written).

    Raises:
        RecordingError: The target exists (and ``overwrite`` is False, or it is not a bag),
            a topic is not canonical, a time is negative, the compression does not suit the
            bag format, or the file system refuses.
    """
    target = bag_location(path)
    ros = bag_ros_version(target)
    chunk_compression(compression, ros, target)
    check_target(target, overwrite=overwrite)
    for topic, table in recording.tables.items():
        checked_spec(topic, table, target)
    sweep_staging(target)
    staging = make_staging(target, "write")
    staged = staging / target.name
    try:
        if ros == 2 and writer == "bulk":
            custom = {OMNICAL_MARKER_KEY: OMNICAL_MARKER, **_travel_data(recording)}
            write_ros2_bag(staged, recording.tables, compression, custom)
        else:
            _write_with_rosbags(recording, staged, ros, compression)
        return put_in_place(staged, target, overwrite=overwrite, divert=divert)
    except RecordingError as err:
        raise renamed_in_message(err, staged, target) from None
    except OSError as err:
        msg = f"{target}: cannot write bag: {err.strerror or err}"
        raise RecordingError(msg) from None
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def put_in_place(
    staged: Path,
    target: Path,
    *,
    overwrite: bool,
    divert: Callable[[], bool] | None = None,
    partial: bool = False,
) -> Path:
    """Move the finished bag ``staged`` to ``target`` (swapped in whole) and return where it went.

    It goes to a free ``.partial`` name instead when ``partial``, a pending stop signal or
    ``divert()`` says so (not inside an output staged as a whole), or when ``target`` has
    meanwhile become something omnical may not replace (RecordingError says where it is).

    Raises:
        RecordingError: The place was taken meanwhile; OSError: a rename failed.
    """
    nested = inside_open_staging(target)
    with held_stops() as stopped:
        if not partial:
            try:
                check_target(target, overwrite=overwrite)  # changed meanwhile?
            except RecordingError as err:
                kept = partial_location(target)
                staged.rename(kept)
                msg = f"{err}; the new recording is kept in {kept}"
                raise RecordingError(msg) from None
        if partial or (not nested and (stopped() or (divert is not None and divert()))):
            kept = partial_location(target)
            staged.rename(kept)
            return kept
        swap_into_place(staged, target)
    return target


def _travel_data(recording: Recording) -> dict[str, str]:
    """The ``custom_data`` entries of the travel of ``/odom`` and ``/ground_truth``
    (:class:`~omnical.recording.summary.TravelTally`), as :class:`BagSink` states them."""
    out = {}
    for topic in (ODOM, GROUND_TRUTH):
        if topic in recording.tables:
            tally = TravelTally()
            tally.add(recording.tables[topic])
            if (stored := tally.result()) is not None:
                out[TRAVEL_KEY_PREFIX + topic] = stored.to_json()
    return out


def _write_with_rosbags(
    recording: Recording, location: Path, ros: RosVersion, compression: BagCompression | None
) -> None:
    """Write ``recording`` at ``location`` through rosbags' writer, message by message."""
    topics: list[str] = []
    times: list[int] = []
    payloads: list[memoryview] = []
    for topic, table in recording.tables.items():
        if len(table):
            payloads.extend(encode_topic(topic, table, ros, location))
            times.extend(table.t_ns.tolist())
            topics.extend([topic] * len(table))
    order = np.argsort(np.asarray(times, dtype=np.int64), kind="stable").tolist()
    sink = BagSink(location, ros, compression)
    sink.open()
    for topic, table in recording.tables.items():
        sink.tally_travel(topic, table)
    try:
        sink.write_messages(
            [topics[i] for i in order], [times[i] for i in order], [payloads[i] for i in order]
        )
        sink.close()
    except BaseException:
        sink.abort()
        raise


def resolve_source(path: str | Path) -> Path:
    """The bag to read for ``path``, applying the :func:`bag_location` rule if needed.

    Every bag read starts here: the bag is checked to be a regular file, or a directory whose
    storage files are regular files (:func:`_regular_storage`), before anything opens it.

    Raises:
        RecordingError: No such bag, a folder that is not a ROS 2 bag, or a FIFO, device or
            socket where a bag or its storage file should be.
    """
    p = Path(path)
    if p.is_dir() and not (p / _METADATA).is_file():
        raise RecordingError(_not_a_bag_folder(p))
    if p.exists():
        return _regular_storage(p)
    alt = bag_location(p)
    if alt != p and (alt / "metadata.yaml").is_file():
        return _regular_storage(alt)
    msg = f"{p}: no such bag"
    raise RecordingError(msg)


_STORAGE_SUFFIXES: Final = frozenset({".mcap", ".db3", ".zstd"})
"""The suffixes of a ROS 2 bag's storage files (as :func:`indexed_mcap` looks for them)."""


def _regular_storage(source: Path) -> Path:
    """``source`` if it is a regular file, or a directory whose storage files (those its
    ``metadata.yaml`` lists and those with a storage suffix) are regular files where present.

    Opening a FIFO blocks until someone writes to it, a device may never end: both are refused
    from their ``stat`` alone (symbolic links followed), naming the path.
    """
    try:
        mode = source.stat().st_mode
    except OSError as err:
        msg = f"{source}: cannot read bag: {err.strerror or err}"
        raise RecordingError(msg) from None
    if stat.S_ISREG(mode):
        return source
    if not stat.S_ISDIR(mode):
        msg = f"{source}: is not a regular file ({file_kind(mode)}), expected a bag"
        raise RecordingError(msg)
    try:
        named = {f.name for f in source.iterdir() if f.suffix in _STORAGE_SUFFIXES}
    except OSError as err:
        msg = f"{source}: cannot read bag: cannot list it ({err.strerror or err})"
        raise RecordingError(msg) from None
    listed: set[str] = set()
    with suppress(RecordingError):  # the reader says what is wrong with metadata.yaml
        listed.update(ros2_bag_files(source)[0])
    for name in sorted(named | listed):
        try:
            mode = (source / name).stat().st_mode
        except OSError:
            continue  # missing or unreadable: the reader says so
        if stat.S_ISDIR(mode) and name not in listed:
            continue  # a folder named like storage (another recording kept inside): not read
        if not stat.S_ISREG(mode):
            msg = (
                f"{source / name}: is not a regular file ({file_kind(mode)}), "
                "expected a bag's storage file"
            )
            raise RecordingError(msg)
    return source


_RECOVER_HINT = "; if its recording was interrupted, `omnical recover` salvages what was flushed"
_DAMAGED = (
    "; the file is complete (closed with its index) but damaged: `omnical recover` cannot mend it"
)


def _not_a_bag_folder(folder: Path) -> str:
    """Why ``folder`` (a directory without ``metadata.yaml``) is not a bag, naming the bag
    files inside it if any."""
    try:
        inside = sorted(f.name for f in folder.iterdir() if f.suffix in {".mcap", ".bag", ".db3"})
    except OSError:
        inside = []
    hint = (
        f"; it holds {', '.join(inside[:3])}{', ...' if len(inside) > 3 else ''}: give a file"
        if inside
        else ""
    )
    msg = f"{folder}: cannot read bag (a folder without {_METADATA}: not a ROS 2 bag{hint})"
    if has_bag_magic(folder):  # a recording's folder whose recording was cut short
        msg += _RECOVER_HINT
    return msg


def unreadable(source: Path, err: Exception) -> RecordingError:
    """The one-line error of a bag rosbags cannot read, with the first line of its reason
    (omnical's index reader words its own: no class name; an MCAP file holding its magic
    alone is said to be so, not what the reader tripped on)."""
    if isinstance(err, MemoryError):  # a corrupt record length, or a healthy bag too big
        return RecordingError(
            f"{source}: cannot read bag (out of memory reading it: a corrupt record length, or "
            "less free memory than its records need)"
        )
    reason = (str(err).splitlines() or [type(err).__name__])[0]
    if not isinstance(err, McapIndexError):
        reason = f"{type(err).__name__}: {reason}"
    if _magic_alone(source):  # nothing flushed: nothing for `omnical recover` either
        return RecordingError(
            f"{source}: cannot read bag (truncated after the MCAP magic: no records)"
        )
    msg = f"{source}: cannot read bag ({reason})"
    if has_bag_magic(source):  # `omnical recover` salvages only a bag that was never closed
        msg += _DAMAGED if bag_is_complete(source) else _RECOVER_HINT
    return RecordingError(msg)


def _magic_alone(source: Path) -> bool:
    """Whether the bag's storage file is an MCAP magic and nothing else (a recorder killed
    before it wrote a record)."""
    file = storage_file(source)
    try:
        return file is not None and file.stat().st_size == len(MCAP_MAGIC) and has_bag_magic(file)
    except OSError:
        return False


def bag_source(path: str | Path) -> tuple[Path, RosVersion]:
    """The bag at ``path`` (:func:`resolve_source`) and its ROS version (1: a ``.bag`` file).

    Raises:
        RecordingError: No such bag, or a ``.bag`` file that is not a ROS 1 bag.
    """
    source = resolve_source(path)
    ros: RosVersion = 1 if source.suffix == ".bag" else 2
    if ros == 1 and source.is_file() and not has_bag_magic(source):
        msg = f"{source}: cannot read bag (not a ROS 1 bag: no '#ROSBAG V2.0' header)"
        raise RecordingError(msg)
    return source, ros


_UNREADABLE: tuple[type[Exception], ...] = (McapIndexError, Ros1ChunkError, *UNREADABLE_BAG_ERRORS)


@contextmanager
def reading_bag(source: Path) -> Iterator[None]:
    """What reading ``source`` raises as one line (:func:`unreadable`); a RecordingError (a
    corrupt time, an undecodable message) already is one, and omnical's own bugs keep their
    traceback."""
    try:
        yield
    except RecordingError:
        raise
    except _UNREADABLE as err:
        raise unreadable(source, err) from None
    except PARSING_ERRORS as err:
        if not raised_while_parsing(err):
            raise
        raise unreadable(source, err) from None


def read_bag(path: str | Path, topics: Collection[str] | None = None) -> Recording:
    """Read the topics omnical knows from a ROS 1 or ROS 2 bag (only ``topics`` if given).

    Marvelmind and JointState topics are recognised by type, the others by name
    (:func:`~omnical.recording.topics.recognise_topic`); other topics are listed in
    ``Recording.skipped_topics``. Row times are bag times. Memory holds the decoded tables.

    Args:
        path: The bag (see :func:`resolve_source`).
        topics: Canonical topic names to read (:data:`omnical.recording.topics.TOPICS`), or
            the names of JointState topics of the bag; None reads every recognised topic.
            Topics the bag lacks are simply absent.

    Raises:
        RecordingError: Missing path, not a bag, truncated or corrupt bag, undecodable message,
            unknown topic name; the message is one line naming the file.
    """
    stream = BagStream(path, topics, batch=DECODE_BATCH, whole=True)
    tables = {part.topic: part.table for part in stream.parts()}
    return Recording(tables, stream.skipped, stream.notes)


STREAM_BATCH: Final = 2_048
"""Messages of one topic decoded (and handed over) at once by :class:`BagStream`."""


class BagStream:
    """The topics omnical reads from a bag, part by part (docs/DESIGN-NOTES.md).

    Parts of about ``batch`` messages join into ``read_bag``'s tables; a part with ``first`` set
    restarts its topic (one read whole: several connections, times going back).

    Args:
        path: The bag (``read_bag``'s rule: a directory, ``.bag``, ``.mcap``, ``.db3``).
        topics: Canonical topics (or the bag's JointState topics) to read; None: every one.
        batch: Messages of one topic per part (about: an MCAP chunk's worth is added at once).
        whole: Read every topic whole, one part each (what :func:`read_bag` does).

    Raises:
        RecordingError: No such bag, or a ``.bag`` file that is not a ROS 1 bag.
    """

    def __init__(
        self,
        path: str | Path,
        topics: Collection[str] | None = None,
        *,
        batch: int = STREAM_BATCH,
        whole: bool = False,
    ) -> None:
        self.source, self.ros = bag_source(path)
        self.wanted = None if topics is None else frozenset(topics)
        self.batch = max(1, int(batch))
        self.read_whole = whole
        self.topics: list[str] = []
        """The topics read, in ``read_bag``'s table order (set once :meth:`parts` is through)."""
        self.whole: list[str] = []
        """The topics that could not be streamed and were read whole (docs/DESIGN-NOTES.md)."""
        self.bag_topics: dict[str, str] = {}
        """Every topic of the bag → its type, as :func:`~omnical.bags.reference_topics.
        bag_topics` lists them (known once :meth:`parts` has started)."""
        self.skipped: dict[str, str] = {}
        """The bag's topics omnical does not read → their type (once :meth:`parts` started)."""
        self._notes: dict[str, list[str]] = {}

    def parts(self) -> Iterator[Part]:
        """The parts of every topic, in reading order (parts of different topics interleave).

        Raises:
            RecordingError: As ``read_bag``: unreadable, truncated or corrupt bag, a time at or
                beyond 2⁶³ ns, an undecodable message, an unknown topic name.
        """
        with reading_bag(self.source):
            yield from self._parts()

    def _parts(self) -> Iterator[Part]:
        source = self.source
        reader = AnyReader([source], default_typestore=typestore(self.ros))
        lean = LeanRos1Reader(source) if self.ros == 1 and source.is_file() else None
        if lean is not None:
            reader.readers = [lean]  # rosbags' reader, without its index of every message
        with reader:
            store = reader.typestore
            self.bag_topics = connection_types(reader.connections)
            complete_store(store, [c.msgtype for c in reader.connections], self.ros)
            check_topics(source, self.wanted, reader)
            decoder = Decoder(
                store, self.ros, str(source), self.wanted, batch=self.batch, whole=self.read_whole
            )
            summary = indexed_mcap(source, reader)
            if summary is not None:
                keyed = [
                    (cid, ch.topic, ch.msgtype) for cid, ch in sorted(summary.channels.items())
                ]
            elif lean is not None:
                keyed = [(c.id, c.topic, c.msgtype) for c in reader.connections]
            else:
                keyed = [(i, c.topic, c.msgtype) for i, c in enumerate(reader.connections)]
            wanted = [
                key for key, topic, msgtype in keyed if decoder.add_connection(key, topic, msgtype)
            ]
            self.skipped = decoder.skipped
            batches: Iterator[tuple[int, Any, list[bytes]]]
            if summary is not None:
                batches = channel_messages(summary, wanted)
            elif lean is not None:
                batches = chunk_messages(lean, wanted)
            else:
                batches = _batched(reader, wanted, self.batch)
            for key, t_ns, payloads in batches:
                yield from decoder.extend(key, t_ns, payloads)
            yield from decoder.finish()
        self.topics, self.whole = decoder.names, decoder.whole_topics
        self._notes = decoder.topic_notes
        if decoder.spoiled:  # read again, whole
            again = BagStream(source, decoder.spoiled, batch=DECODE_BATCH, whole=True)
            yield from again.parts()
            self._notes.update(again._notes)

    @property
    def notes(self) -> tuple[str, ...]:
        """What the cleaning did, as :attr:`Recording.notes` of ``read_bag`` (once through)."""
        return tuple(note for name in self.topics for note in self._notes.get(name, []))


def _batched(
    reader: AnyReader, wanted: list[int], batch: int
) -> Iterator[tuple[int, list[int], list[bytes]]]:
    """The messages of connections ``wanted`` (indexes in ``reader.connections``) through
    rosbags, ``batch`` of one connection at a time: (index, times ns, payloads)."""
    conns = list(reader.connections)
    index = {(id(conns[i].owner), conns[i].id): i for i in wanted}
    held: dict[int, tuple[list[int], list[bytes]]] = {}
    for conn, stamp, payload in reader.messages(connections=[conns[i] for i in wanted]):
        key = index[(id(conn.owner), conn.id)]
        times, payloads = held.setdefault(key, ([], []))
        times.append(stamp)
        payloads.append(payload)
        if len(payloads) >= batch:
            yield key, times, payloads
            del held[key]
    for key, (times, payloads) in held.items():
        yield key, times, payloads


def connection_types(connections: Iterable[Connection]) -> dict[str, str]:
    """Every topic of ``connections`` → its message type (types joined by ``|`` if connections
    of one topic differ), in their order."""
    types: dict[str, list[str]] = {}
    for conn in connections:
        if conn.msgtype not in types.setdefault(conn.topic, []):
            types[conn.topic].append(conn.msgtype)
    return {topic: "|".join(names) for topic, names in types.items()}


def check_topics(source: Path, topics: Collection[str] | None, reader: AnyReader) -> None:
    """Refuse topic names that are neither canonical nor a JointState topic of the bag."""
    if topics is None:
        return
    joints = set()
    for conn in reader.connections:
        hit = recognise_topic(conn.topic, conn.msgtype)
        if hit is not None and hit[1] == MessageKind.JOINT_STATE:
            joints.add(hit[0])
    if unknown := sorted(set(topics) - set(TOPICS) - joints):
        have = ", ".join(sorted({f"{c.topic} ({c.msgtype})" for c in reader.connections}))
        msg = (
            f"{source}: no topic {', '.join(unknown)} that omnical can read; the bag has: "
            f"{have or 'no topics'}"
        )
        if joints:
            msg += f" (wheel encoders: {', '.join(sorted(joints))})"
        raise RecordingError(msg)


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
