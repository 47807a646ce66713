"""Bag writers: canonical topics in, ROS 2 MCAP directory or ROS 1 file out.

:func:`write_ros2_bag` writes a whole recording in bulk (MCAP records built in numpy);
:class:`BagSink` writes through rosbags message by message (ROS 1, the recorder). zstd / lz4 chunks.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Final, Literal

import numpy as np
import yaml
from rosbags.interfaces import Connection
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag1 import WriterError as Writer1Error
from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.rosbag2 import WriterError as Writer2Error
from rosbags.rosbag2.storage_mcap import McapWriter as RosbagsMcapWriter

from omnical import __version__
from omnical.bags.mcapwrite import CHUNK_SIZE, WINDOW, McapWriter, MessageStream
from omnical.bags.messages import Frame, Packed, encode_packed, encode_table
from omnical.bags.typestores import RosVersion, typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Table
from omnical.recording.summary import TRAVEL_KEY_PREFIX, TravelTally
from omnical.recording.topics import GROUND_TRUTH, ODOM, TOPICS, TopicSpec, spec_of

__all__ = [
    "DEFAULT_COMPRESSION",
    "OMNICAL_CALLERID",
    "OMNICAL_MARKER",
    "OMNICAL_MARKER_KEY",
    "ROS2_METADATA_VERSION",
    "BagCompression",
    "BagSink",
    "checked_spec",
    "chunk_compression",
    "encode_topic",
    "topic_spec",
    "write_ros2_bag",
]

BagCompression = Literal["auto", "zstd", "lz4", "bz2"]
"""Chunk compression of a written bag: ``auto`` is zstd for ROS 2 MCAP, lz4 for ROS 1."""

DEFAULT_COMPRESSION: Final[BagCompression] = "auto"
"""What :func:`~omnical.bags.bag.write_bag` and the recorder use unless told otherwise."""

_CHUNK_COMPRESSIONS: Final[dict[int, tuple[str, ...]]] = {2: ("zstd",), 1: ("lz4", "bz2")}

ROS2_METADATA_VERSION: Final[Literal[8]] = 8
"""rosbag2 metadata version written (the oldest rosbags writes; Jazzy reads it natively)."""

OMNICAL_MARKER_KEY: Final = "omnical.writer"
"""Key of omnical's marker in a ROS 2 bag's ``custom_data`` (``metadata.yaml`` and MCAP)."""

OMNICAL_MARKER: Final = "omnical"
"""Value of omnical's marker: the bag was written by omnical (write_bag or BagRecorder)."""

OMNICAL_CALLERID: Final = "/omnical"
"""Caller id of every connection of a ROS 1 bag omnical writes (its marker there)."""

_WRITE_ERRORS: Final[tuple[type[Exception], ...]] = (Writer1Error, Writer2Error, OSError)
"""What rosbags' writers and the file system raise when a bag cannot be written."""


def topic_spec(topic: str, where: Path, columns: tuple[str, ...] | None = None) -> TopicSpec:
    """The spec of a canonical topic, or of a JointState topic of another name given its
    ``columns``; RecordingError for a topic omnical cannot write."""
    spec = TOPICS.get(topic) if columns is None else spec_of(topic, columns)
    if spec is None:
        msg = f"{where}: cannot write topic {topic}: not one of {', '.join(TOPICS)}"
        raise RecordingError(msg)
    return spec


def chunk_compression(compression: str | None, ros_version: RosVersion, where: Path) -> str | None:
    """The chunk compression to write for ``compression`` (``auto``, a name, or None = none).

    Raises:
        RecordingError: The bag format cannot compress its chunks that way (zstd is ROS 2
            MCAP only, lz4 and bz2 are ROS 1 only).
    """
    if compression is None:
        return None
    allowed = _CHUNK_COMPRESSIONS[ros_version]
    if compression == "auto":
        return allowed[0]
    if compression not in allowed:
        msg = (
            f"{where}: a ROS {ros_version} bag cannot use {compression!r} chunk compression "
            f"(choose {', '.join(allowed)}, 'auto' or None)"
        )
        raise RecordingError(msg)
    return compression


def checked_spec(topic: str, table: Table, where: Path) -> TopicSpec:
    """The spec ``table`` is written with as ``topic`` (see :func:`topic_spec`).

    Raises:
        RecordingError: The topic is not canonical or a time is negative (bags store
            unsigned times).
    """
    spec = topic_spec(topic, where, table.names)
    if (t_min := int(table.t_ns.min()) if len(table) else 0) < 0:
        msg = f"{where}: topic {topic} has a negative time ({t_min} ns)"
        raise RecordingError(msg)
    return spec


def encode_topic(
    topic: str, table: Table, ros_version: RosVersion, where: Path, *, seq_start: int = 0
) -> list[memoryview]:
    """Serialise ``table`` as messages of canonical ``topic``, one per row.

    ``seq_start`` numbers the ROS 1 header ``seq`` of the first row.

    Raises:
        RecordingError: The topic is not canonical or a time is negative (bags store
            unsigned times).
    """
    spec = checked_spec(topic, table, where)
    return encode_table(spec, table, ros_version, seq_start=seq_start)


def _rows(table: Table, lo: int, hi: int) -> Table:
    """Rows ``lo:hi`` of ``table`` (views, no copy)."""
    return Table(table.t_ns[lo:hi], {k: v[lo:hi] for k, v in table.columns.items()})


def _by_time(table: Table) -> Table:
    """``table`` with its rows in time order (ties keep their order)."""
    if bool(np.all(np.diff(table.t_ns) >= 0)):
        return table
    return table.take(np.argsort(table.t_ns, kind="stable"))


def _stream_encoder(spec: TopicSpec, table: Table) -> Callable[[int, int, Frame], Packed]:
    def encode(lo: int, hi: int, frame: Frame) -> Packed:
        return encode_packed(spec, _rows(table, lo, hi), 2, frame=frame)

    return encode


def _yaml(data: object) -> str:
    """YAML in block style with sorted keys, as rosbags writes ``metadata.yaml``."""
    dumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)
    return yaml.dump(data, Dumper=dumper, default_flow_style=False, allow_unicode=True)


def write_ros2_bag(
    location: Path,
    tables: Mapping[str, Table],
    compression: str | None,
    custom_data: Mapping[str, str],
    *,
    chunk_size: int = CHUNK_SIZE,
    window: int = WINDOW,
) -> None:
    """Write ``tables`` as the ROS 2 bag directory ``location`` (MCAP storage), in bulk.

    Topics without rows are left out. Connection numbers (by first message), message order
    (by time, ties in ``tables`` order) and metadata (version 8, ``ros_distro: omnical``) are
    those rosbags' writer gives when fed in that order.

    Args:
        location: The bag directory to create (must not exist).
        tables: Canonical topic (or JointState topic) → rows.
        compression: ``zstd`` chunks, or None for uncompressed ones.
        custom_data: The rosbag2 ``custom_data`` (strings).
        chunk_size: Uncompressed bytes after which an MCAP chunk is closed.
        window: Messages encoded at a time (memory holds this many encoded).

    Raises:
        RecordingError: A topic cannot be written (see :func:`checked_spec`), or
            ``compression`` is not a ROS 2 one.
        OSError: The file system refuses.
    """
    chunk = chunk_compression(compression, 2, location)
    entries = []
    for rank, (topic, table) in enumerate(tables.items()):
        spec = checked_spec(topic, table, location)
        if len(table):
            ordered = _by_time(table)
            entries.append((int(ordered.t_ns[0]), rank, topic, spec, ordered))
    store = typestore(2)
    location.mkdir(mode=0o755, parents=True)
    storage = location / f"{location.name}.mcap"
    schemas: dict[str, int] = {}
    channels: dict[str, tuple[int, str, str]] = {}  # topic → channel id, type, type hash
    with storage.open("xb") as stream:
        writer = McapWriter(
            stream,
            profile="ros2",
            library=f"omnical-{__version__}",
            compression="zstd" if chunk == "zstd" else "",
            chunk_size=chunk_size,
            window=window,
        )
        for _, _, topic, spec, _ in sorted(entries, key=lambda e: e[:2]):
            msgtype = spec.ros2_type
            if msgtype not in schemas:
                msgdef, _ = store.generate_msgdef(msgtype, ros_version=2)
                idl = msgdef.startswith("=" * 80 + "\nIDL: ")
                schemas[msgtype] = writer.add_schema(
                    msgtype, "ros2idl" if idl else "ros2msg", msgdef.encode()
                )
            cid = writer.add_channel(schemas[msgtype], topic, "cdr", {"offered_qos_profiles": ""})
            channels[topic] = (cid, msgtype, store.hash_rihs01(msgtype))
        writer.write_streams(
            [
                MessageStream(channels[topic][0], table.t_ns, _stream_encoder(spec, table))
                for _, _, topic, spec, table in entries
            ]
        )
        counts = {topic: len(table) for _, _, topic, _, table in entries}
        start = min((int(e[4].t_ns[0]) for e in entries), default=2**63 - 1)
        end = max((int(e[4].t_ns[-1]) for e in entries), default=0)
        info = _rosbag2_information(storage.name, channels, counts, start, end, custom_data)
        writer.add_metadata("rosbag2", {"serialized_metadata": _yaml(info).strip()})
        writer.finish()
    (location / "metadata.yaml").write_text(
        _yaml({"rosbag2_bagfile_information": info}), encoding="utf-8"
    )


def _rosbag2_information(
    storage: str,
    channels: Mapping[str, tuple[int, str, str]],
    counts: Mapping[str, int],
    start: int,
    end: int,
    custom_data: Mapping[str, str],
) -> dict[str, object]:
    """The ``rosbag2_bagfile_information`` of a bag, field for field as rosbags writes it
    (version 8; an empty bag starts at 2^63 - 1 and lasts 0 ns, as there)."""
    duration = max(0, end - start)
    count = sum(counts.values())
    return {
        "version": ROS2_METADATA_VERSION,
        "storage_identifier": "mcap",
        "relative_file_paths": [storage],
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": [
            {
                "topic_metadata": {
                    "name": topic,
                    "type": msgtype,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": "",
                    "type_description_hash": rihs01,
                },
                "message_count": counts[topic],
            }
            for topic, (_, msgtype, rihs01) in sorted(channels.items(), key=lambda c: c[1][0])
        ],
        "compression_format": "",
        "compression_mode": "",
        "files": [
            {
                "path": storage,
                "starting_time": {"nanoseconds_since_epoch": start},
                "duration": {"nanoseconds": duration},
                "message_count": count,
            }
        ],
        "custom_data": dict(custom_data) or None,
        "ros_distro": "omnical",
    }


class BagSink:
    """Writes tables of canonical topics to one bag through rosbags.

    Args:
        location: Bag directory (ROS 2) or ``.bag`` file (ROS 1); must not exist.
        ros_version: 2 for a ROS 2 bag with MCAP storage, 1 for a ROS 1 bag.
        compression: Chunk compression (see :func:`chunk_compression`); None writes the bag
            uncompressed.

    Raises:
        RecordingError: ``compression`` does not suit the bag format.
    """

    def __init__(
        self,
        location: Path,
        ros_version: RosVersion,
        compression: str | None = DEFAULT_COMPRESSION,
    ) -> None:
        self.location = location
        self.ros_version: RosVersion = ros_version
        self.compression = chunk_compression(compression, ros_version, location)
        self.message_count = 0
        self._connections: dict[str, Connection] = {}
        self._sequence: dict[str, int] = {}
        self._writer: Writer1 | Writer2 | None = None
        self._travel: dict[str, TravelTally] = {}

    def open(self) -> None:
        """Create the bag on disk."""
        writer: Writer1 | Writer2
        try:
            if self.ros_version == 2:
                writer = Writer2(
                    self.location,
                    version=ROS2_METADATA_VERSION,
                    storage_plugin=StoragePlugin.MCAP,
                )
                if self.compression == "zstd":
                    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
                writer.set_custom_data(OMNICAL_MARKER_KEY, OMNICAL_MARKER)
            else:
                writer = Writer1(self.location)
                if self.compression is not None:
                    writer.set_compression(Writer1.CompressionFormat[self.compression.upper()])
            writer.open()
        except _WRITE_ERRORS as err:
            msg = f"{self.location}: cannot create bag: {err}"
            raise RecordingError(msg) from None
        self._writer = writer

    def _checked(self) -> Writer1 | Writer2:
        if self._writer is None:
            msg = f"{self.location}: bag is not open"
            raise RecordingError(msg)
        return self._writer

    def connection(self, topic: str) -> Connection:
        """The connection of a canonical topic (or a JointState topic), added on first use."""
        conn = self._connections.get(topic)
        if conn is None:
            spec = spec_of(topic)  # any other name was checked as a JointState when encoded
            assert spec is not None
            writer = self._checked()
            store = typestore(self.ros_version)
            if isinstance(writer, Writer2):
                conn = writer.add_connection(topic, spec.ros2_type, typestore=store)
            else:
                conn = writer.add_connection(
                    topic, spec.ros1_type, typestore=store, callerid=OMNICAL_CALLERID
                )
            self._connections[topic] = conn
        return conn

    def write_messages(
        self,
        topics: Sequence[str],
        times_ns: Sequence[int],
        payloads: Sequence[memoryview | bytes],
    ) -> None:
        """Write messages in the order given (topic, bag time in ns, payload)."""
        writer = self._checked()
        conns = {t: self.connection(t) for t in dict.fromkeys(topics)}
        write = writer.write
        for topic, t_ns, payload in zip(topics, times_ns, payloads, strict=True):
            write(conns[topic], t_ns, payload)
        self.message_count += len(payloads)

    def write_table(self, topic: str, table: Table) -> None:
        """Write every row of ``table`` (sorted by time) as a message of ``topic``."""
        if len(table) == 0:
            return
        seq = self._sequence.get(topic, 0)
        payloads = encode_topic(topic, table, self.ros_version, self.location, seq_start=seq)
        self._sequence[topic] = seq + len(table)
        self.write_messages([topic] * len(table), table.t_ns.tolist(), payloads)
        self.tally_travel(topic, table)

    def tally_travel(self, topic: str, table: Table) -> None:
        """Add ``table`` (rows written as ``topic``) to the travel of ``/odom`` and
        ``/ground_truth`` stated in ``custom_data`` on close (:class:`TravelTally`)."""
        if topic in (ODOM, GROUND_TRUTH):
            self._travel.setdefault(topic, TravelTally()).add(table)

    def flush(self) -> None:
        """Close the chunk being filled and push it to disk (fsync)."""
        writer = self._checked()
        if isinstance(writer, Writer2):
            storage = writer.storage
            if isinstance(storage, RosbagsMcapWriter):
                if storage.chunk.msgs:
                    storage.close_chunk()
                storage.bio.flush()
                os.fsync(storage.bio.fileno())
        elif writer.bio is not None:
            chunk = writer.chunks[-1]
            if chunk.connections:
                writer.write_chunk(chunk)
            writer.bio.flush()
            os.fsync(writer.bio.fileno())

    def close(self) -> None:
        """Write index, summary and metadata; the bag is complete afterwards."""
        writer = self._checked()
        self._writer = None
        if isinstance(writer, Writer2):
            for topic, tally in self._travel.items():
                if (stored := tally.result()) is not None:
                    writer.set_custom_data(TRAVEL_KEY_PREFIX + topic, stored.to_json())
        try:
            writer.close()
        except _WRITE_ERRORS as err:
            _abort(writer)
            msg = f"{self.location}: cannot finish bag: {err}"
            raise RecordingError(msg) from None
        except BaseException:
            _abort(writer)
            raise

    def abort(self) -> None:
        """Stop writing without index (what a crash would leave)."""
        writer, self._writer = self._writer, None
        if writer is not None:
            _abort(writer)


def _abort(writer: Writer1 | Writer2) -> None:
    """``writer.abort()``; a write error there (the disk full again) leaves what is on disk
    as it is, and the error that led here is the one to report."""
    with contextlib.suppress(*_WRITE_ERRORS):
        writer.abort()
