"""From the serialised messages of bag connections to a :class:`Recording`.

Shared by :func:`omnical.recording.bag.read_bag` (messages from rosbags' AnyReader) and
:func:`omnical.recording.recover.recover_bag` (messages scanned from an unfinished file).
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys.store import Typestore

from omnical.errors import RecordingError
from omnical.recording.messages import decode_messages
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import TOPICS, MessageKind, recognise_topic
from omnical.recording.typestores import RosVersion

__all__ = ["DECODE_BATCH", "RawConnection", "StreamDecoder", "recording_from_connections"]


@dataclass
class RawConnection:
    """The messages of one bag connection: topic, type, bag times (ns) and payloads."""

    topic: str
    msgtype: str
    times_ns: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)


DECODE_BATCH = 16_384
"""Messages of one connection held as raw payloads before they are decoded into columns."""


@dataclass
class _Pending:
    """A wanted connection being decoded: its canonical topic and what has come so far."""

    name: str
    kind: MessageKind
    topic: str
    msgtype: str
    times: list[NDArray[np.int64]] = field(default_factory=list)
    single_times: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)
    parts: list[dict[str, NDArray[Any]]] = field(default_factory=list)


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
        recognise: Maps (topic, type) to (canonical topic, kind), or None if not used.
    """

    def __init__(
        self,
        store: Typestore,
        ros_version: RosVersion,
        source: str,
        topics: Collection[str] | None = None,
        *,
        batch: int = DECODE_BATCH,
        recognise: Callable[[str, str], tuple[str, MessageKind] | None] = recognise_topic,
    ) -> None:
        self.recognise = recognise
        self.store = store
        self.ros_version: RosVersion = ros_version
        self.source = source
        self.topics = None if topics is None else frozenset(topics)
        self.batch = batch
        self.skipped: dict[str, str] = {}
        self._pending: list[_Pending] = []

    def add_connection(self, topic: str, msgtype: str) -> int | None:
        """Register a connection; a handle if its messages are wanted, else None."""
        hit = self.recognise(topic, msgtype)
        if hit is None:
            self.skipped[topic] = msgtype
            return None
        name, kind = hit
        if self.topics is not None and name not in self.topics:
            return None
        self._pending.append(_Pending(name, kind, topic, msgtype))
        return len(self._pending) - 1

    def add(self, handle: int, t_ns: int, payload: bytes) -> None:
        """One message of a wanted connection."""
        pending = self._pending[handle]
        pending.single_times.append(t_ns)
        pending.payloads.append(payload)
        if len(pending.payloads) >= self.batch:
            self._decode(pending)

    def extend(self, handle: int, t_ns: NDArray[np.int64], payloads: list[bytes]) -> None:
        """Messages of a wanted connection: times (N,) ns and their payloads."""
        pending = self._pending[handle]
        self._seal_times(pending)
        pending.times.append(np.asarray(t_ns, dtype=np.int64))
        pending.payloads.extend(payloads)
        if len(pending.payloads) >= self.batch:
            self._decode(pending)

    @staticmethod
    def _seal_times(pending: _Pending) -> None:
        if pending.single_times:
            pending.times.append(np.asarray(pending.single_times, dtype=np.int64))
            pending.single_times = []

    def _decode(self, pending: _Pending) -> None:
        self._seal_times(pending)
        spec = TOPICS[pending.name]
        where = f"{self.source}: topic {pending.topic}"
        raws, pending.payloads = pending.payloads, []
        columns = decode_messages(
            pending.kind, pending.msgtype, raws, self.store, self.ros_version, where
        )
        cast = {c: _as_dtype(columns[c], spec.dtype_of(c), where) for c in spec.column_names}
        pending.parts.append(cast)

    def recording(self) -> Recording:
        """The decoded tables (canonical topic order, rows sorted by time) and skipped topics."""
        grouped: dict[str, list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]]] = {}
        for pending in self._pending:
            if pending.payloads or not pending.parts:
                self._decode(pending)
            t_ns = np.concatenate(pending.times) if pending.times else np.zeros(0, np.int64)
            parts = pending.parts
            columns = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
            pending.parts, pending.times = [], []
            grouped.setdefault(pending.name, []).append((t_ns, columns))
        tables: dict[str, Table] = {}
        for name in (n for n in TOPICS if n in grouped):
            chunks = grouped[name]
            t_ns = np.concatenate([c[0] for c in chunks]) if len(chunks) > 1 else chunks[0][0]
            columns = (
                {k: np.concatenate([c[1][k] for c in chunks]) for k in chunks[0][1]}
                if len(chunks) > 1
                else chunks[0][1]
            )
            if t_ns.size > 1 and bool(np.any(t_ns[1:] < t_ns[:-1])):
                order = np.argsort(t_ns, kind="stable")
                t_ns, columns = t_ns[order], {k: v[order] for k, v in columns.items()}
            tables[name] = Table(t_ns, columns)
        return Recording(tables, self.skipped)


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
            decoder.extend(handle, np.asarray(conn.times_ns, dtype=np.int64), conn.payloads)
    return decoder.recording()


def _as_dtype(values: NDArray[Any], dtype: np.dtype[Any], where: str) -> NDArray[Any]:
    if values.dtype == dtype or dtype.kind == "O":
        return values
    if dtype.kind in "iu" and values.size:
        info = np.iinfo(dtype)
        if values.min() < info.min or values.max() > info.max:
            msg = f"{where}: values out of range for {dtype}"
            raise RecordingError(msg)
    return values.astype(dtype)
