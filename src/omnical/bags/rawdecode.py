"""From the serialised messages of bag connections to a :class:`Recording`, checked once.

For ``read_bag`` and ``recover_bag``: sorted, duplicates and unusable rows dropped (counted in
:attr:`Recording.notes`), times at or beyond 2⁶³ ns refused.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable
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
    "MAX_ABS_VALUE",
    "MAX_TIME_NS",
    "Cleaning",
    "Pending",
    "RawConnection",
    "StreamDecoder",
    "bag_times",
    "clean_rows",
    "recording_from_connections",
]

MAX_TIME_NS = 2**63 - 1
"""The latest bag time omnical represents (int64 nanoseconds: 2262-04-11)."""

_NON_NEGATIVE = frozenset({"distance_m"})
"""Float columns that cannot be negative (a range)."""

_NON_FINITE_OK = frozenset({"ranges_m"})
"""Float columns whose infinities and NaN are meaningful (REP 117 LaserScan ranges)."""

_UNBOUNDED = frozenset({"position_rad"})
"""Float columns exempt from the ±10⁶ bound: a JointState position may be a cumulative encoder
count (10⁶ counts of a 777-count wheel are 1 287 turns, a few hundred metres)."""


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
"""Payload bytes of one connection held before they are decoded (2 MiB): with a batch of
large messages (odometry, IMU: 300–700 B) on every connection the raw payloads held between
decodes were a third of ``read_bag``'s peak."""


@dataclass
class Pending:
    """The messages of one wanted connection come so far, held as payloads until decoded."""

    name: str
    kind: MessageKind
    msgtype: str
    where: str
    times: list[NDArray[np.int64]] = field(default_factory=list)
    single_times: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)
    last_ns: int | None = None

    def seal_times(self) -> None:
        """Turn the times added one by one into an array (before an array is appended)."""
        if self.single_times:
            self.times.append(bag_times(self.single_times, self.where))
            self.single_times = []

    def decode(
        self, store: Typestore, ros_version: RosVersion
    ) -> tuple[NDArray[np.int64], dict[str, NDArray[Any]]]:
        """The times and columns of the messages held, which are let go: decoded
        (:func:`omnical.bags.messages.decode_messages`), each column cast to the topic's dtype.

        Raises:
            RecordingError: A message cannot be decoded, or an integer is out of its column's
                range.
        """
        self.seal_times()
        raws, self.payloads = self.payloads, []
        t_ns = np.concatenate(self.times) if self.times else np.zeros(0, np.int64)
        self.times = []
        spec = spec_of(self.name)
        assert spec is not None  # recognised topics all have a spec
        columns = decode_messages(self.kind, self.msgtype, raws, store, ros_version, self.where)
        return t_ns, {
            c: _as_dtype(columns[c], spec.dtype_of(c), self.where) for c in spec.column_names
        }


@dataclass
class _Pending(Pending):
    """A connection :class:`StreamDecoder` decodes: its decoded parts and backward steps."""

    parts: list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]] = field(default_factory=list)
    backward: int = 0
    payload_bytes: int = 0


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


class StreamDecoder:
    """Decodes the messages of a bag's connections into topic tables as they are read.

    Payloads are kept only until :data:`DECODE_BATCH` of one connection have come, then
    decoded into columns, so memory holds the decoded tables plus one batch per connection,
    not the serialised messages of the whole recording.

    Args:
        store: Type store knowing every wanted connection's type.
        ros_version: Serialisation of the payloads (1 or 2).
        source: The bag's path, for error messages.
        topics: Canonical topics to decode (None: all); recognised connections of other
            topics are ignored, unrecognised ones are listed as skipped either way.
        batch: Payloads of one connection decoded at once.
    """

    def __init__(
        self,
        store: Typestore,
        ros_version: RosVersion,
        source: str,
        topics: Collection[str] | None = None,
        *,
        batch: int = DECODE_BATCH,
    ) -> None:
        self.store = store
        self.ros_version: RosVersion = ros_version
        self.source = source
        self.topics = None if topics is None else frozenset(topics)
        self.batch = batch
        self.skipped: dict[str, str] = {}
        self._pending: list[_Pending] = []

    def add_connection(self, topic: str, msgtype: str) -> int | None:
        """Register a connection; a handle if its messages are wanted, else None."""
        hit = recognise_topic(topic, msgtype)
        if hit is None:
            self.skipped[topic] = msgtype
            return None
        name, kind = hit
        if self.topics is not None and name not in self.topics:
            return None
        self._pending.append(_Pending(name, kind, msgtype, f"{self.source}: topic {topic}"))
        return len(self._pending) - 1

    def add(self, handle: int, t_ns: int, payload: bytes) -> None:
        """One message of a wanted connection."""
        pending = self._pending[handle]
        if pending.last_ns is not None and t_ns < pending.last_ns:
            pending.backward += 1
        pending.last_ns = t_ns
        pending.single_times.append(t_ns)
        pending.payloads.append(payload)
        pending.payload_bytes += len(payload)
        if len(pending.payloads) >= self.batch or pending.payload_bytes >= DECODE_BYTES:
            self._decode(pending)

    def extend(self, handle: int, t_ns: NDArray[Any] | list[int], payloads: list[bytes]) -> None:
        """Messages of a wanted connection: times (N,) ns (signed or unsigned) and payloads."""
        pending = self._pending[handle]
        pending.seal_times()
        times = bag_times(t_ns, pending.where)
        if times.size:
            previous = [] if pending.last_ns is None else [pending.last_ns]
            steps = np.diff(np.concatenate([np.asarray(previous, dtype=np.int64), times]))
            pending.backward += int(np.count_nonzero(steps < 0))
            pending.last_ns = int(times[-1])
        pending.times.append(times)
        pending.payloads.extend(payloads)
        pending.payload_bytes += sum(map(len, payloads))
        if len(pending.payloads) >= self.batch or pending.payload_bytes >= DECODE_BYTES:
            self._decode(pending)

    def _decode(self, pending: _Pending) -> None:
        pending.parts.append(pending.decode(self.store, self.ros_version))
        pending.payload_bytes = 0

    def recording(self) -> Recording:
        """The decoded tables (canonical topic order, rows sorted by time, cleaned), skipped
        topics, and what the cleaning did (:attr:`Recording.notes`)."""
        grouped: dict[str, list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]]] = {}
        backward: dict[str, int] = {}
        for pending in self._pending:
            backward[pending.name] = backward.get(pending.name, 0) + pending.backward
            if pending.payloads or not pending.parts:
                self._decode(pending)
            parts, pending.parts = pending.parts, []
            t_ns = np.concatenate([t for t, _ in parts])
            grouped.setdefault(pending.name, []).append((t_ns, _joined([c for _, c in parts])))
        tables: dict[str, Table] = {}
        notes: list[str] = []
        others = sorted(n for n in grouped if n not in TOPICS)
        for name in [*(n for n in TOPICS if n in grouped), *others]:
            chunks = grouped.pop(name)
            t_ns = np.concatenate([c[0] for c in chunks]) if len(chunks) > 1 else chunks[0][0]
            columns = _joined([c[1] for c in chunks]) if len(chunks) > 1 else chunks[0][1]
            del chunks
            if t_ns.size > 1 and bool(np.any(t_ns[1:] < t_ns[:-1])):
                order = np.argsort(t_ns, kind="stable")
                t_ns = t_ns[order]
                for k in columns:  # a column at a time: each old one is released as it goes
                    columns[k] = columns[k][order]
            if backward.get(name):
                notes.append(f"{name}: {backward[name]} message(s) out of time order, sorted")
            tables[name] = _cleaned(name, t_ns, columns, notes)
        return Recording(tables, self.skipped, tuple(notes))


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

    Args:
        connections: Raw connections of a bag.
        store: Type store knowing every connection's type.
        ros_version: Serialisation of the payloads (1 or 2).
        source: The bag's path, for error messages.
        topics: Canonical topics to decode (None: every recognised one).

    Raises:
        RecordingError: A recognised message cannot be decoded.
    """
    decoder = StreamDecoder(store, ros_version, source, topics)
    for conn in connections:
        handle = decoder.add_connection(conn.topic, conn.msgtype)
        if handle is not None:
            decoder.extend(handle, np.asarray(conn.times_ns, dtype=np.uint64), conn.payloads)
    return decoder.recording()


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


def clean_rows(table: Table, previous: Table | None = None) -> tuple[Table, Cleaning]:
    """``table`` without rows holding an unusable value and without exact duplicates.

    A row is a duplicate when its time and values equal the row before it, as read (before
    cleaning). ``previous``, the last row of the part read before ``table`` (one row, as read),
    lets a long topic be cleaned part by part with the same result as at once.
    """
    if len(table) == 0:
        return table, Cleaning()
    drop, cleaning = _rows_to_drop(table, previous)
    return (table.take(~drop) if drop.any() else table), cleaning


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


def _cleaned(
    name: str, t_ns: NDArray[np.int64], columns: dict[str, NDArray[Any]], notes: list[str]
) -> Table:
    """The table of ``t_ns`` and ``columns`` without rows holding an unusable value and without
    exact duplicates (:func:`clean_rows`), the rows dropped a column at a time (``columns`` is
    consumed: each column is released once its kept rows are copied)."""
    table = Table(t_ns, columns)
    if len(table) == 0:
        return table
    drop, cleaning = _rows_to_drop(table, None)
    notes.extend(cleaning.notes(name))
    if not drop.any():
        return table
    del table
    keep = ~drop
    t_ns = t_ns[keep]
    for k in columns:
        columns[k] = columns[k][keep]
    return Table(t_ns, columns)


def _joined(parts: list[dict[str, NDArray[Any]]]) -> dict[str, NDArray[Any]]:
    """The parts' columns concatenated, a column at a time: each column's parts are released
    (popped from ``parts``) once joined, so the peak is the table plus one column."""
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
