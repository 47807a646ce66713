"""Streaming read of a bag: each topic's rows a part at a time, cleaned as ``read_bag`` does.

:class:`BagStream` yields parts of about :data:`STREAM_BATCH` messages that join into ``read_bag``'s
tables; a part with ``first`` set restarts its topic (one that had to be read whole).
"""

from __future__ import annotations

from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from numpy.typing import NDArray
from rosbags.highlevel import AnyReader
from rosbags.typesys.store import Typestore

from omnical.bags.bag import bag_source, check_topics, indexed_mcap, read_bag, reading_bag
from omnical.bags.mcapindex import channel_messages
from omnical.bags.rawdecode import Cleaning, Pending, bag_times, clean_rows
from omnical.bags.ros1chunks import LeanRos1Reader, chunk_messages
from omnical.bags.typestores import complete_store, typestore
from omnical.errors import RecordingError
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import TOPICS, MessageKind, recognise_topic

__all__ = ["STREAM_BATCH", "BagStream", "Part", "read_selected"]

STREAM_BATCH: Final = 2_048
"""Messages of one topic decoded (and handed over) at once."""


@dataclass(frozen=True)
class Part:
    """Consecutive rows of one topic (cleaned, in time order); ``first``: its rows start here."""

    topic: str
    table: Table
    first: bool


@dataclass
class _Topic(Pending):
    """A canonical topic being streamed: its one connection and what has come so far."""

    previous: Table | None = None  # the last row handed over, as read (before cleaning)
    widths: dict[str, tuple[int, ...]] | None = None
    cleaning: Cleaning = field(default_factory=Cleaning)
    started: bool = False
    backward: bool = False

    def spoil(self) -> None:
        """Its messages go back in time: ``read_bag`` sorts them, so it is read whole later."""
        self.backward = True
        self.times, self.single_times, self.payloads, self.previous = [], [], [], None


class BagStream:
    """The topics omnical reads from a bag, part by part (docs/DESIGN-NOTES.md).

    Args:
        path: The bag (``read_bag``'s rule: a directory, ``.bag``, ``.mcap``, ``.db3``).
        topics: Canonical topics (or the bag's JointState topics) to read; None: every one.
        batch: Messages of one topic per part (about: an MCAP chunk's worth is added at once).

    Raises:
        RecordingError: No such bag, or a ``.bag`` file that is not a ROS 1 bag.
    """

    def __init__(
        self,
        path: str | Path,
        topics: Collection[str] | None = None,
        *,
        batch: int = STREAM_BATCH,
    ) -> None:
        self.source, self.ros = bag_source(path)
        self.wanted = None if topics is None else frozenset(topics)
        self.batch = max(1, int(batch))
        self.topics: list[str] = []
        """The topics read, in ``read_bag``'s table order (set once :meth:`parts` is through)."""
        self.whole: list[str] = []
        """The topics that could not be streamed and were read whole (docs/DESIGN-NOTES.md)."""
        self.bag_topics: dict[str, str] = {}
        """Every topic of the bag → its type, as :func:`~omnical.bags.reference_topics.
        bag_topics` lists them (known once :meth:`parts` has started)."""
        self._notes: dict[str, list[str]] = {}

    @property
    def notes(self) -> tuple[str, ...]:
        """What the cleaning did, as :attr:`Recording.notes` of ``read_bag`` (once through)."""
        return tuple(note for name in self.topics for note in self._notes.get(name, []))

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
            types: dict[str, list[str]] = {}
            for conn in reader.connections:
                if conn.msgtype not in types.setdefault(conn.topic, []):
                    types[conn.topic].append(conn.msgtype)
            self.bag_topics = {topic: "|".join(names) for topic, names in types.items()}
            complete_store(store, [c.msgtype for c in reader.connections], self.ros)
            check_topics(source, self.wanted, reader)
            summary = indexed_mcap(source, reader)
            if summary is not None:
                connections = [
                    (cid, ch.topic, ch.msgtype) for cid, ch in sorted(summary.channels.items())
                ]
            elif lean is not None:
                connections = [(c.id, c.topic, c.msgtype) for c in reader.connections]
            else:
                connections = [(i, c.topic, c.msgtype) for i, c in enumerate(reader.connections)]
            streamed, names = self._register(connections)
            if summary is not None:
                for cid, t_ns, payloads in channel_messages(summary, streamed):
                    yield from self._extend(streamed[cid], store, t_ns, payloads)
            elif lean is not None:
                for cid, t_ns, payloads in chunk_messages(lean, streamed):
                    yield from self._extend(streamed[cid], store, t_ns, payloads)
            elif streamed:
                conns = list(reader.connections)
                keys = {(id(conns[i].owner), conns[i].id): i for i in streamed}
                wanted = [conns[i] for i in streamed]
                for conn, stamp, payload in reader.messages(connections=wanted):
                    topic = streamed[keys[(id(conn.owner), conn.id)]]
                    if topic.last_ns is not None and stamp < topic.last_ns:
                        topic.spoil()
                    if not topic.backward:
                        topic.last_ns = stamp
                        topic.single_times.append(stamp)
                        topic.payloads.append(payload)
                        if len(topic.payloads) >= self.batch:
                            yield from self._flush(topic, store)
            for topic in streamed.values():
                if not topic.backward and (topic.payloads or not topic.started):
                    yield from self._flush(topic, store)
        order = [n for n in TOPICS if n in names] + sorted(n for n in names if n not in TOPICS)
        self.topics = order
        for topic in streamed.values():
            if topic.backward:
                self.whole.append(topic.name)
            else:
                self._notes[topic.name] = topic.cleaning.notes(topic.name)
        self.whole = [n for n in order if n in self.whole or n not in self._notes]
        for name in self.whole:
            recording = read_bag(source, [name])
            self._notes[name] = list(recording.notes)
            yield Part(name, recording.topic(name), first=True)

    def _register(
        self, connections: list[tuple[int, str, str]]
    ) -> tuple[dict[int, _Topic], set[str]]:
        """The streamed connections (key → topic) and the names of every topic read."""
        hits: dict[str, list[tuple[int, MessageKind, str, str]]] = {}
        for key, topic, msgtype in connections:
            hit = recognise_topic(topic, msgtype)
            if hit is None or (self.wanted is not None and hit[0] not in self.wanted):
                continue
            hits.setdefault(hit[0], []).append((key, hit[1], msgtype, topic))
        streamed: dict[int, _Topic] = {}
        for name, conns in hits.items():
            if len(conns) == 1:  # several connections are merged by time: read whole
                key, kind, msgtype, topic = conns[0]
                where = f"{self.source}: topic {topic}"
                streamed[key] = _Topic(name, kind, msgtype, where)
        return streamed, set(hits)

    def _extend(
        self, topic: _Topic, store: Typestore, t_ns: NDArray[np.uint64], payloads: list[bytes]
    ) -> Iterator[Part]:
        """Messages of ``topic`` as read; a part once ``batch`` of them have come."""
        if topic.backward:
            return
        times = bag_times(t_ns, topic.where)
        if times.size:
            if (topic.last_ns is not None and int(times[0]) < topic.last_ns) or bool(
                np.any(times[1:] < times[:-1])
            ):
                topic.spoil()
                return
            topic.last_ns = int(times[-1])
        topic.times.append(times)
        topic.payloads.extend(payloads)
        if len(topic.payloads) >= self.batch:
            yield from self._flush(topic, store)

    def _flush(self, topic: _Topic, store: Typestore) -> Iterator[Part]:
        """Decode what has come of ``topic``, clean it, hand it over."""
        times, columns = topic.decode(store, self.ros)
        widths = {k: v.shape[1:] for k, v in columns.items()}
        if topic.widths is None:
            topic.widths = widths
        elif widths != topic.widths and times.size:
            changed = next(k for k in widths if widths[k] != topic.widths[k])
            msg = (
                f"{topic.where}: column {changed} holds {widths[changed]} values per message, "
                f"earlier messages {topic.widths[changed]}; a sequence read as a column "
                "keeps one length per topic"
            )
            raise RecordingError(msg)
        table = Table(times, columns)
        cleaned, cleaning = clean_rows(table, topic.previous)
        topic.cleaning = topic.cleaning + cleaning
        if len(table):
            topic.previous = table.take([len(table) - 1])
        first, topic.started = not topic.started, True
        yield Part(topic.name, cleaned, first)


class _Growing:
    """A topic's columns grown part by part in buffers doubled when full: their pages are
    touched only as rows arrive, and a buffer outgrown is returned whole (no heap of small
    parts, nor a second copy of the topic when they are joined)."""

    def __init__(self) -> None:
        self.rows = 0
        self.buffers: dict[str, NDArray[np.generic]] = {}

    def extend(self, t_ns: NDArray[np.int64], columns: Mapping[str, NDArray[np.generic]]) -> None:
        added = {"": t_ns, **columns}
        end = self.rows + t_ns.shape[0]
        for name, values in added.items():
            buffer = self.buffers.get(name)
            dtype = values.dtype if buffer is None else np.result_type(buffer, values)
            if buffer is None or buffer.shape[0] < end or dtype != buffer.dtype:
                size = max(end, 2 * (0 if buffer is None else buffer.shape[0]), 4096)
                grown = np.empty((size, *values.shape[1:]), dtype=dtype)
                if buffer is not None:
                    grown[: self.rows] = buffer[: self.rows]
                self.buffers[name] = buffer = grown
            buffer[self.rows : end] = values
        self.rows = end

    def table(self) -> Table:
        """The rows so far (views of the buffers)."""
        cut = {name: buffer[: self.rows] for name, buffer in self.buffers.items()}
        t_ns = cut.pop("") if cut else np.empty(0, dtype=np.int64)
        return Table(t_ns.astype(np.int64, copy=False), cut)


def read_selected(
    path: str | Path, topics: Collection[str], columns: Mapping[str, Sequence[str]]
) -> Recording:
    """``read_bag(path, topics)`` keeping only ``columns[topic]`` of the topics named there
    (every column of the others), read part by part through :class:`BagStream`: the same rows,
    times and notes, without the whole tables' decoding buffers nor the columns not kept.

    Raises:
        RecordingError: as ``read_bag``.
    """
    stream = BagStream(path, topics)
    growing: dict[str, _Growing] = {}
    for part in stream.parts():
        names = columns.get(part.topic, part.table.names)
        if part.first or part.topic not in growing:
            growing[part.topic] = _Growing()
        growing[part.topic].extend(part.table.t_ns, {n: part.table[n] for n in names})
    tables = {name: growing.pop(name).table() for name in stream.topics if name in growing}
    return Recording(tables, notes=stream.notes)
