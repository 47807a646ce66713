"""The in-memory recording: one columnar table per topic, rows stamped in integer nanoseconds.

:class:`Recording` (immutable, read-only arrays) is what every service reads, bags its on-disk form;
:class:`RecordingBuilder` collects rows during a run and sorts each topic once, in ``build``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import RecordingError
from omnical.recording.topics import TOPICS

__all__ = ["MAX_ABS_VALUE", "Recording", "RecordingBuilder", "Table"]

_NS_PER_S = 1_000_000_000

MAX_ABS_VALUE = 1e6
"""Largest magnitude of a float column kept when reading a bag (larger is corrupt)."""


def _frozen(array: NDArray[Any]) -> NDArray[Any]:
    view = array.view()
    view.setflags(write=False)
    return view


@dataclass(frozen=True, eq=False)
class Table:
    """Rows of one topic: times ``t_ns`` (N,) int64 and named columns, each (N,) or (N, ...).

    Args:
        t_ns: Bag time of each row, integer nanoseconds, shape (N,).
        columns: Column name (with unit) → array whose first axis has length N.
    """

    t_ns: NDArray[np.int64]
    columns: Mapping[str, NDArray[Any]]

    def __post_init__(self) -> None:
        t_ns = np.asarray(self.t_ns)
        if t_ns.ndim != 1 or (t_ns.size and t_ns.dtype.kind not in "iu"):
            msg = f"t_ns must be a 1-D integer array, got shape {t_ns.shape} dtype {t_ns.dtype}"
            raise RecordingError(msg)
        object.__setattr__(self, "t_ns", _frozen(t_ns.astype(np.int64, copy=False)))
        cols: dict[str, NDArray[Any]] = {}
        for name, values in self.columns.items():
            array = np.asarray(values)
            if array.ndim == 0 or array.shape[0] != t_ns.shape[0]:
                msg = f"column {name!r} has shape {array.shape}, expected ({t_ns.shape[0]}, ...)"
                raise RecordingError(msg)
            cols[name] = _frozen(array)
        object.__setattr__(self, "columns", MappingProxyType(cols))

    def __len__(self) -> int:
        return int(self.t_ns.shape[0])

    def __getitem__(self, name: str) -> NDArray[Any]:
        try:
            return self.columns[name]
        except KeyError:
            msg = f"no column {name!r} (columns: {', '.join(self.columns) or 'none'})"
            raise RecordingError(msg) from None

    @property
    def names(self) -> tuple[str, ...]:
        """Column names, in order."""
        return tuple(self.columns)

    def t_s(self, t0_ns: int | None = None) -> NDArray[np.float64]:
        """Row times in float seconds since ``t0_ns`` (default: the first row), shape (N,).

        The difference is taken in integers first, so no precision is lost to the epoch.
        """
        if t0_ns is None:
            t0_ns = int(self.t_ns[0]) if len(self) else 0
        return (self.t_ns - np.int64(t0_ns)).astype(np.float64) / _NS_PER_S

    def take(self, rows: ArrayLike) -> Table:
        """A new table with the rows selected by an index array or boolean mask."""
        index = np.asarray(rows)
        return Table(self.t_ns[index], {k: v[index] for k, v in self.columns.items()})

    def between(self, start_ns: int, end_ns: int) -> Table:
        """Rows with ``start_ns <= t_ns < end_ns`` (rows must be sorted by time)."""
        lo, hi = np.searchsorted(self.t_ns, [start_ns, end_ns], side="left")
        return self.take(np.arange(lo, hi))


@dataclass(frozen=True, eq=False)
class Recording:
    """A set of topic tables, plus the topics a bag held that omnical did not recognise.

    Args:
        tables: Topic name → table, rows sorted by time.
        skipped_topics: Topic name → message type of each topic left out when reading a bag.
        notes: What reading a bag cleaned, one line each with its count (messages out of
            time order sorted, duplicated messages and non-finite or out-of-range values
            dropped); empty for a clean bag or a recording built in memory.
    """

    tables: Mapping[str, Table]
    skipped_topics: Mapping[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "tables", MappingProxyType(dict(self.tables)))
        object.__setattr__(self, "skipped_topics", MappingProxyType(dict(self.skipped_topics)))
        object.__setattr__(self, "notes", tuple(self.notes))

    @property
    def topics(self) -> tuple[str, ...]:
        """Topic names, in insertion order."""
        return tuple(self.tables)

    def has(self, name: str) -> bool:
        """Whether the recording holds topic ``name`` with at least one row."""
        table = self.tables.get(name)
        return table is not None and len(table) > 0

    def topic(self, name: str) -> Table:
        """The table of topic ``name``; RecordingError naming it if the recording lacks it."""
        try:
            return self.tables[name]
        except KeyError:
            have = ", ".join(self.tables) or "none"
            msg = f"recording has no topic {name} (topics: {have})"
            raise RecordingError(msg) from None

    def _bounds(self) -> tuple[int, int]:
        times = [t.t_ns for t in self.tables.values() if len(t)]
        if not times:
            msg = "recording is empty: it has no start, end or duration"
            raise RecordingError(msg)
        return min(int(t.min()) for t in times), max(int(t.max()) for t in times)

    @property
    def start_ns(self) -> int:
        """Time of the earliest row over all topics, ns (RecordingError if empty)."""
        return self._bounds()[0]

    @property
    def end_ns(self) -> int:
        """Time of the latest row over all topics, ns (RecordingError if empty)."""
        return self._bounds()[1]

    @property
    def duration_s(self) -> float:
        """``end_ns - start_ns`` in seconds."""
        start, end = self._bounds()
        return (end - start) / _NS_PER_S

    @property
    def message_count(self) -> int:
        """Total number of rows over all topics."""
        return sum(len(t) for t in self.tables.values())

    def with_table(self, name: str, table: Table) -> Recording:
        """A copy with topic ``name`` set to ``table`` (added or replaced)."""
        return Recording({**self.tables, name: table}, self.skipped_topics, self.notes)

    def without(self, *names: str) -> Recording:
        """A copy without the given topics (absent names are ignored)."""
        drop = set(names)
        kept = {k: v for k, v in self.tables.items() if k not in drop}
        return Recording(kept, self.skipped_topics, self.notes)

    def merged(self, other: Recording) -> Recording:
        """Topics of both recordings; a topic in both is concatenated and re-sorted by time.

        Raises:
            RecordingError: A shared topic has different columns in the two recordings.
        """
        tables = dict(self.tables)
        for name, theirs in other.tables.items():
            ours = tables.get(name)
            if ours is None:
                tables[name] = theirs
                continue
            if ours.names != theirs.names:
                msg = f"cannot merge topic {name}: columns {ours.names} != {theirs.names}"
                raise RecordingError(msg)
            tables[name] = _sorted_table(
                np.concatenate([ours.t_ns, theirs.t_ns]),
                {k: np.concatenate([ours[k], theirs[k]]) for k in ours.names},
            )
        return Recording(
            tables, {**self.skipped_topics, **other.skipped_topics}, self.notes + other.notes
        )


def _sorted_table(t_ns: NDArray[np.int64], columns: Mapping[str, NDArray[Any]]) -> Table:
    if t_ns.size > 1 and bool(np.any(t_ns[1:] < t_ns[:-1])):
        order = np.argsort(t_ns, kind="stable")
        return Table(t_ns[order], {k: v[order] for k, v in columns.items()})
    return Table(t_ns, columns)


class _TopicBuffer:
    """Pending rows of one topic: single rows as dicts, batches as arrays, in arrival order."""

    __slots__ = ("chunks", "keys", "keyset", "rows", "times")

    def __init__(self, keys: tuple[str, ...]) -> None:
        self.keys = keys
        self.keyset = frozenset(keys)
        self.times: list[int] = []
        self.rows: list[dict[str, Any]] = []
        self.chunks: list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]] = []

    def seal_rows(self, topic: str) -> None:
        if not self.times:
            return
        t_ns = _int_times(topic, self.times)
        cols = {k: np.array([r[k] for r in self.rows]) for k in self.keys}
        self.chunks.append((t_ns, cols))
        self.times, self.rows = [], []


def _int_times(topic: str, values: ArrayLike) -> NDArray[np.int64]:
    t_ns = np.asarray(values)
    if t_ns.ndim != 1 or (t_ns.size and t_ns.dtype.kind not in "iu"):
        msg = f"topic {topic}: t_ns must be integer nanoseconds (got dtype {t_ns.dtype})"
        raise RecordingError(msg)
    return t_ns.astype(np.int64, copy=False)


class RecordingBuilder:
    """Collects rows topic by topic and builds a :class:`Recording` sorted by time.

    Canonical topics (:data:`omnical.recording.topics.TOPICS`) must be given exactly their
    columns, cast to the topic's dtypes; other topics take the columns of their first row.
    ``add`` keeps rows as Python objects until ``build``; ``add_many`` appends whole arrays.
    """

    def __init__(self) -> None:
        self._buffers: dict[str, _TopicBuffer] = {}

    def _buffer(self, topic: str, keys: Iterable[str]) -> _TopicBuffer:
        buffer = self._buffers.get(topic)
        if buffer is None:
            spec = TOPICS.get(topic)
            expected = spec.column_names if spec is not None else tuple(keys)
            buffer = self._buffers[topic] = _TopicBuffer(expected)
        return buffer

    def _check_keys(self, topic: str, buffer: _TopicBuffer, keys: Iterable[str]) -> None:
        got = set(keys)
        if got != buffer.keyset:
            missing = sorted(buffer.keyset - got)
            extra = sorted(got - buffer.keyset)
            msg = f"topic {topic}: columns missing {missing}, unexpected {extra}"
            raise RecordingError(msg)

    def add(self, topic: str, t_ns: int, **values: Any) -> None:
        """Append one row to ``topic`` at bag time ``t_ns`` (integer ns)."""
        buffer = self._buffers.get(topic) or self._buffer(topic, values)
        if values.keys() != buffer.keyset:
            self._check_keys(topic, buffer, values)
        buffer.times.append(t_ns)
        buffer.rows.append(values)

    def write_rows(self, topic: str, t_ns: ArrayLike, **columns: ArrayLike) -> None:
        """:meth:`add_many`: a builder is a row sink (:class:`~omnical.experiment.rig.RowSink`)."""
        self.add_many(topic, t_ns, **columns)

    def add_many(self, topic: str, t_ns: ArrayLike, **columns: ArrayLike) -> None:
        """Append rows to ``topic``: ``t_ns`` (N,) integer ns, each column (N, ...)."""
        buffer = self._buffer(topic, columns)
        self._check_keys(topic, buffer, columns)
        times = _int_times(topic, t_ns)
        arrays = {k: np.asarray(columns[k]) for k in buffer.keys}
        for name, array in arrays.items():
            if array.ndim == 0 or array.shape[0] != times.shape[0]:
                msg = f"topic {topic}: column {name!r} has shape {array.shape}, t_ns {times.shape}"
                raise RecordingError(msg)
        buffer.seal_rows(topic)
        buffer.chunks.append((times, arrays))

    def __len__(self) -> int:
        return sum(len(b.times) + sum(len(c[0]) for c in b.chunks) for b in self._buffers.values())

    def build(self) -> Recording:
        """The recording of every row added so far, each topic sorted by time (stable)."""
        tables: dict[str, Table] = {}
        for topic, buffer in self._buffers.items():
            buffer.seal_rows(topic)
            if not buffer.chunks:
                continue
            spec = TOPICS.get(topic)
            t_ns = np.concatenate([c[0] for c in buffer.chunks])
            columns: dict[str, NDArray[Any]] = {}
            for name in buffer.keys:
                parts = [c[1][name] for c in buffer.chunks]
                joined = np.concatenate(parts) if len(parts) > 1 else parts[0]
                if spec is not None:
                    joined = _cast(topic, name, joined, spec.dtype_of(name))
                columns[name] = joined
            tables[topic] = _sorted_table(t_ns, columns)
        return Recording(tables)


def _cast(topic: str, name: str, values: NDArray[Any], dtype: np.dtype[Any]) -> NDArray[Any]:
    """Cast a built column to its canonical dtype, refusing lossy integer conversions."""
    if values.dtype == dtype:
        return values
    if dtype.kind == "O":
        return np.array([str(v) for v in values.ravel()], dtype=object).reshape(values.shape)
    if dtype.kind in "iu" and values.size:
        exact = values.dtype.kind in "biu" or (
            values.dtype.kind == "f" and bool(np.all(values == np.round(values)))
        )
        if not exact:
            msg = f"topic {topic}: column {name!r} must hold integers ({dtype})"
            raise RecordingError(msg)
        info = np.iinfo(dtype)
        if values.min() < info.min or values.max() > info.max:
            msg = f"topic {topic}: column {name!r} out of range for {dtype}"
            raise RecordingError(msg)
    try:
        return values.astype(dtype)
    except (TypeError, ValueError):
        msg = f"topic {topic}: column {name!r} cannot be converted to {dtype}"
        raise RecordingError(msg) from None
