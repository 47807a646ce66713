"""From the serialised messages of bag connections to cleaned topic tables: :class:`Decoder`.

The one decoder of ``read_bag``, ``BagStream`` and ``recover_bag``: sorted, duplicates and
unusable rows dropped (counted in :attr:`Recording.notes`), times at or beyond 2⁶³ ns refused.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys.store import Typestore

from omnical.bags.messages import decode_messages
from omnical.bags.typestores import RosVersion
from omnical.errors import RecordingError
from omnical.recording.recording import MAX_ABS_VALUE, Recording, Table
from omnical.recording.topics import TOPICS, MessageKind, recognise_topic, spec_of

__all__ = [
    "DECODE_BATCH",
    "MAX_TIME_NS",
    "Decoder",
    "Part",
    "RawConnection",
    "recording_from_connections",
]

MAX_TIME_NS = 2**63 - 1
"""The latest bag time omnical represents (int64 nanoseconds: 2262-04-11)."""

_NON_NEGATIVE = frozenset({"distance_m"})
"""Float columns that cannot be negative (a range)."""

_NON_FINITE_OK = frozenset({"ranges_m"})
"""Float columns whose infinities and NaN are meaningful (REP 117 LaserScan ranges)."""

_UNBOUNDED = frozenset({"position_rad"})
"""Float columns exempt from the ±10⁶ bound (a JointState position may be an encoder count)."""


@dataclass
class RawConnection:
    """The messages of one bag connection: topic, type, bag times (ns) and payloads."""

    topic: str
    msgtype: str
    times_ns: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)


DECODE_BATCH = 16_384
"""Messages of one connection held as raw payloads before they are decoded into columns."""
DECODE_BYTES = 1 << 21
"""Payload bytes of one connection held before they are decoded (2 MiB)."""


def bag_times(values: Any, where: str) -> NDArray[np.int64]:
    """Bag times (a list of ints or an unsigned array) as int64 ns, refusing times ≥ 2⁶³ ns.

    Raises:
        RecordingError: A time is at or beyond 2⁶³ ns (or negative): a corrupt bag.
    """
    if isinstance(values, np.ndarray) and values.dtype.kind == "u":
        huge = int(np.count_nonzero(values > MAX_TIME_NS))
        if huge:
            raise _huge_times(where, huge)
        return values.astype(np.int64)
    try:
        times = np.asarray(values, dtype=np.int64)
    except OverflowError:
        huge = sum(1 for v in values if int(v) > MAX_TIME_NS or int(v) < 0)
        raise _huge_times(where, huge) from None
    if times.size and int(times.min()) < 0:
        raise _huge_times(where, int(np.count_nonzero(times < 0)))
    return times


def _huge_times(where: str, count: int) -> RecordingError:
    msg = (
        f"{where}: {count} message(s) with a bag time at or beyond 2^63 ns (after 2262-04-11) "
        "or negative; the bag's times are corrupt"
    )
    return RecordingError(msg)


@dataclass(frozen=True)
class Cleaning:
    """What :func:`clean_rows` dropped from a table: rows with an unusable value, duplicates."""

    bad: int = 0
    duplicates: int = 0

    def __add__(self, other: Cleaning) -> Cleaning:
        return Cleaning(self.bad + other.bad, self.duplicates + other.duplicates)

    def notes(self, name: str) -> list[str]:
        """The notes :attr:`Recording.notes` holds for topic ``name``, in order."""
        notes = []
        if self.bad:
            notes.append(
                f"{name}: {self.bad} message(s) with non-finite or out-of-range values dropped"
            )
        if self.duplicates:
            notes.append(f"{name}: {self.duplicates} duplicated message(s) dropped")
        return notes


@dataclass(frozen=True)
class Part:
    """Consecutive rows of one topic (cleaned, in time order); ``first``: its rows start here."""

    topic: str
    table: Table
    first: bool


@dataclass
class _Connection:
    """A wanted connection: its payloads until decoded, its decoded parts (a whole topic's),
    and (a streamed topic's) the last row handed over and what cleaning dropped so far."""

    name: str
    kind: MessageKind
    msgtype: str
    where: str
    whole: bool
    times: list[NDArray[np.int64]] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)
    payload_bytes: int = 0
    last_ns: int | None = None
    backward: int = 0
    widths: dict[str, tuple[int, ...]] | None = None
    parts: list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]] = field(default_factory=list)
    previous: Table | None = None
    cleaning: Cleaning = field(default_factory=Cleaning)
    started: bool = False
    spoiled: bool = False

    def decode(
        self, store: Typestore, ros_version: RosVersion
    ) -> tuple[NDArray[np.int64], dict[str, NDArray[Any]]]:
        """The times and columns of the messages held (then let go), cast to the topic's dtypes.

        Raises:
            RecordingError: A message cannot be decoded, an integer is out of its column's
                range, or a column's width differs from the earlier messages'.
        """
        raws, self.payloads, self.payload_bytes = self.payloads, [], 0
        t_ns = np.concatenate(self.times) if self.times else np.zeros(0, np.int64)
        self.times = []
        spec = spec_of(self.name)
        assert spec is not None  # recognised topics all have a spec
        decoded = decode_messages(self.kind, self.msgtype, raws, store, ros_version, self.where)
        columns = {
            c: _as_dtype(decoded[c], spec.dtype_of(c), self.where) for c in spec.column_names
        }
        widths = {k: v.shape[1:] for k, v in columns.items()}
        if self.widths is None:
            self.widths = widths
        elif widths != self.widths and t_ns.size:
            changed = next(k for k in widths if widths[k] != self.widths[k])
            msg = (
                f"{self.where}: column {changed} holds {widths[changed]} values per message, "
                f"earlier messages {self.widths[changed]}; a sequence read as a column "
                "keeps one length per topic"
            )
            raise RecordingError(msg)
        return t_ns, columns


class Decoder:
    """Decodes the messages of a bag's connections into parts of topic tables, as they come.

    A topic of one connection is streamed (parts of about ``batch`` rows, cleaned as they go);
    others (every topic when ``whole``) are merged by time and cleaned at the end, one part.
    A streamed topic whose times go back is dropped and named in :attr:`spoiled` (read it
    again whole).

    Args:
        store: Type store knowing every wanted connection's type.
        ros_version: Serialisation of the payloads (1 or 2).
        source: The bag's path, for error messages.
        topics: Canonical topics to decode (None: all); recognised connections of other
            topics are ignored, unrecognised ones are listed as skipped either way.
        batch: Messages of one connection decoded at once (and of a streamed part).
        whole: Read every topic whole (what ``read_bag`` does).
    """

    def __init__(
        self,
        store: Typestore,
        ros_version: RosVersion,
        source: str,
        topics: Collection[str] | None = None,
        *,
        batch: int = DECODE_BATCH,
        whole: bool = False,
    ) -> None:
        self.store = store
        self.ros_version: RosVersion = ros_version
        self.source = source
        self.topics = None if topics is None else frozenset(topics)
        self.batch = max(1, int(batch))
        self.whole = whole
        self.skipped: dict[str, str] = {}
        """Unrecognised topic → its type."""
        self.spoiled: list[str] = []
        """Streamed topics whose times went back: dropped, to be read whole."""
        self.names: list[str] = []
        """The topics read, in table order (canonical first; set once :meth:`finish` is done)."""
        self.whole_topics: list[str] = []
        """The topics of :attr:`names` read whole or spoiled (set by :meth:`finish`)."""
        self.topic_notes: dict[str, list[str]] = {}
        """What reading did to each topic's table (set by :meth:`finish`)."""
        self._conns: dict[int, _Connection] = {}

    @property
    def notes(self) -> tuple[str, ...]:
        """What reading did to the tables (:attr:`Recording.notes`), once finished."""
        return tuple(note for name in self.names for note in self.topic_notes.get(name, []))

    def add_connection(self, key: int, topic: str, msgtype: str) -> bool:
        """Register connection ``key`` (all of them before the first message); wanted?"""
        hit = recognise_topic(topic, msgtype)
        if hit is None:
            self.skipped[topic] = msgtype
            return False
        name, kind = hit
        if self.topics is not None and name not in self.topics:
            return False
        conn = _Connection(name, kind, msgtype, f"{self.source}: topic {topic}", whole=self.whole)
        for other in self._conns.values():
            if other.name == name:  # several connections are merged by time: whole
                other.whole = conn.whole = True
        self._conns[key] = conn
        return True

    def extend(self, key: int, t_ns: NDArray[Any] | list[int], payloads: list[bytes]) -> list[Part]:
        """Messages of connection ``key``: times (N,) ns (signed or unsigned) and payloads;
        the part it completes, if any."""
        conn = self._conns[key]
        if conn.spoiled:
            return []
        times = bag_times(t_ns, conn.where)
        if times.size:
            back = int(np.count_nonzero(times[1:] < times[:-1]))
            back += conn.last_ns is not None and int(times[0]) < conn.last_ns
            if back and not conn.whole:
                conn.spoiled = True
                conn.times, conn.payloads, conn.previous = [], [], None
                self.spoiled.append(conn.name)
                return []
            conn.backward += back
            conn.last_ns = int(times[-1])
        conn.times.append(times)
        conn.payloads.extend(payloads)
        if conn.whole:  # a streamed part is small: only a whole topic's bytes are counted
            conn.payload_bytes += sum(map(len, payloads))
        if len(conn.payloads) >= self.batch or conn.payload_bytes >= DECODE_BYTES:
            return self._decode(conn)
        return []

    def finish(self) -> Iterator[Part]:
        """The rest: the last part of each streamed topic, then each whole topic's one part."""
        for conn in self._conns.values():
            if not (conn.whole or conn.spoiled) and (conn.payloads or not conn.started):
                yield from self._decode(conn)
        names = {conn.name for conn in self._conns.values()}
        self.names = [n for n in TOPICS if n in names] + sorted(n for n in names if n not in TOPICS)
        for name in self.names:
            conns = [c for c in self._conns.values() if c.name == name]
            if conns[0].whole or conns[0].spoiled:
                self.whole_topics.append(name)
            if conns[0].whole:
                yield Part(name, self._merged(name, conns), first=True)
            elif not conns[0].spoiled:
                self.topic_notes[name] = conns[0].cleaning.notes(name)

    def _decode(self, conn: _Connection) -> list[Part]:
        """Decode what has come of ``conn``; streamed, clean it and hand it over."""
        times, columns = conn.decode(self.store, self.ros_version)
        if conn.whole:
            conn.parts.append((times, columns))
            return []
        last = Table(times, columns).take([-1]) if times.size else conn.previous
        cleaned, cleaning = clean_rows(times, columns, conn.previous)
        conn.cleaning, conn.previous = conn.cleaning + cleaning, last
        first, conn.started = not conn.started, True
        return [Part(conn.name, cleaned, first)]

    def _merged(self, name: str, conns: list[_Connection]) -> Table:
        """The whole table of topic ``name``: its connections joined, sorted, cleaned."""
        notes = self.topic_notes[name] = []
        chunks = []
        for conn in conns:
            if conn.payloads or not conn.parts:
                self._decode(conn)
            parts, conn.parts = conn.parts, []
            chunks.append((np.concatenate([t for t, _ in parts]), _joined([c for _, c in parts])))
        t_ns = np.concatenate([c[0] for c in chunks]) if len(chunks) > 1 else chunks[0][0]
        columns = _joined([c[1] for c in chunks]) if len(chunks) > 1 else chunks[0][1]
        del chunks
        if t_ns.size > 1 and bool(np.any(t_ns[1:] < t_ns[:-1])):
            order = np.argsort(t_ns, kind="stable")
            t_ns = t_ns[order]
            for k in columns:  # a column at a time: each old one is released as it goes
                columns[k] = columns[k][order]
        if backward := sum(c.backward for c in conns):
            notes.append(f"{name}: {backward} message(s) out of time order, sorted")
        table, cleaning = clean_rows(t_ns, columns)
        notes.extend(cleaning.notes(name))
        return table


def recording_from_connections(
    connections: Iterable[RawConnection],
    store: Typestore,
    ros_version: RosVersion,
    source: str,
    topics: Collection[str] | None = None,
) -> Recording:
    """Decode recognised connections into topic tables; list the others as skipped.

    Several connections that map to one canonical topic (two hedgehogs, a topic recorded
    under two names) are merged and sorted by time.

    Raises:
        RecordingError: A recognised message cannot be decoded.
    """
    decoder = Decoder(store, ros_version, source, topics, whole=True)
    conns = list(connections)
    wanted = [k for k, c in enumerate(conns) if decoder.add_connection(k, c.topic, c.msgtype)]
    for key in wanted:
        times = np.asarray(conns[key].times_ns, dtype=np.uint64)
        decoder.extend(key, times, conns[key].payloads)
    tables = {part.topic: part.table for part in decoder.finish()}
    return Recording(tables, decoder.skipped, decoder.notes)


def clean_rows(
    t_ns: NDArray[np.int64], columns: dict[str, NDArray[Any]], previous: Table | None = None
) -> tuple[Table, Cleaning]:
    """The table of ``t_ns`` and ``columns`` without rows holding an unusable value and without
    exact duplicates (time and values equal to the row before, as read); ``columns`` is consumed.

    ``previous``, the last row of the part before (as read), makes cleaning part by part give
    the same result as at once.
    """
    table = Table(t_ns, columns)
    if len(table) == 0:
        return table, Cleaning()
    drop, cleaning = _rows_to_drop(table, previous)
    if not drop.any():
        return table, cleaning
    del table
    keep = ~drop
    for k in columns:
        columns[k] = columns[k][keep]
    return Table(t_ns[keep], columns), cleaning


def _rows_to_drop(table: Table, previous: Table | None) -> tuple[NDArray[np.bool_], Cleaning]:
    """The rows :func:`clean_rows` drops (a mask) and what they are."""
    n = len(table)
    bad = np.zeros(n, dtype=bool)
    for column in table.names:
        values = table[column]
        if values.dtype.kind != "f" or column in _NON_FINITE_OK:
            continue
        flat = values.reshape(n, -1)
        bad |= ~np.all(np.isfinite(flat), axis=1)
        if column not in _UNBOUNDED:
            bad |= np.any(np.abs(flat) > MAX_ABS_VALUE, axis=1)
        if column in _NON_NEGATIVE:
            bad |= np.any(flat < 0.0, axis=1)
    # same[i]: row i repeats the row before it (row 0: the last row of ``previous``)
    same = np.zeros(n, dtype=bool)
    if previous is not None and len(previous):
        same[0] = _same_row(table, previous)
    if n > 1:
        same[1:] = table.t_ns[1:] == table.t_ns[:-1]
        for column in table.names:
            if not same[1:].any():
                break
            values = table[column]
            equal = np.asarray(values[1:] == values[:-1], dtype=bool).reshape(n - 1, -1)
            same[1:] &= np.all(equal, axis=1)
    # a duplicate of a dropped row is dropped with it
    same &= ~bad
    drop = bad | same
    cleaning = Cleaning(int(np.count_nonzero(bad)), int(np.count_nonzero(same)))
    return drop, cleaning


def _same_row(table: Table, previous: Table) -> bool:
    """Whether the first row of ``table`` repeats the last row of ``previous``."""
    if int(table.t_ns[0]) != int(previous.t_ns[-1]) or table.names != previous.names:
        return False
    for column in table.names:
        first, last = table[column][0], previous[column][-1]
        if np.shape(first) != np.shape(last) or not bool(np.all(first == last)):
            return False
    return True


def _joined(parts: list[dict[str, NDArray[Any]]]) -> dict[str, NDArray[Any]]:
    """The parts' columns concatenated, a column at a time (each popped from ``parts`` once
    joined: the peak is the table plus one column)."""
    joined: dict[str, NDArray[Any]] = {}
    for k in list(parts[0]):
        joined[k] = np.concatenate([p.pop(k) for p in parts])
    return joined


def _as_dtype(values: NDArray[Any], dtype: np.dtype[Any], where: str) -> NDArray[Any]:
    if values.dtype == dtype or dtype.kind == "O":
        return values
    if dtype.kind in "iu" and values.size:
        info = np.iinfo(dtype)
        if values.min() < info.min or values.max() > info.max:
            msg = f"{where}: values out of range for {dtype}"
            raise RecordingError(msg)
    return values.astype(dtype)
