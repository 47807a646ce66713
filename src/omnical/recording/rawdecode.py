"""From the serialised messages of bag connections to a :class:`Recording`.

Shared by :func:`omnical.recording.bag.read_bag` (messages from rosbags' AnyReader) and
:func:`omnical.recording.recover.recover_bag` (messages scanned from an unfinished file).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from rosbags.typesys.store import Typestore

from omnical.errors import RecordingError
from omnical.recording.messages import decode_messages
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import TOPICS, recognise_topic
from omnical.recording.typestores import RosVersion

__all__ = ["RawConnection", "recording_from_connections"]


@dataclass
class RawConnection:
    """The messages of one bag connection: topic, type, bag times (ns) and payloads."""

    topic: str
    msgtype: str
    times_ns: list[int] = field(default_factory=list)
    payloads: list[bytes] = field(default_factory=list)


def recording_from_connections(
    connections: Iterable[RawConnection],
    store: Typestore,
    ros_version: RosVersion,
    source: str,
) -> Recording:
    """Decode recognised connections into topic tables; list the others as skipped.

    Several connections that map to one canonical topic (two hedgehogs, a topic recorded
    under two names) are merged and sorted by time.

    Args:
        connections: Raw connections of a bag.
        store: Type store knowing every connection's type.
        ros_version: Serialisation of the payloads (1 or 2).
        source: The bag's path, for error messages.

    Raises:
        RecordingError: A recognised message cannot be decoded.
    """
    parts: dict[str, list[tuple[NDArray[np.int64], dict[str, NDArray[Any]]]]] = {}
    skipped: dict[str, str] = {}
    for conn in connections:
        hit = recognise_topic(conn.topic, conn.msgtype)
        if hit is None:
            skipped[conn.topic] = conn.msgtype
            continue
        name, kind = hit
        spec = TOPICS[name]
        where = f"{source}: topic {conn.topic}"
        columns = decode_messages(kind, conn.msgtype, conn.payloads, store, ros_version, where)
        cast = {c: _as_dtype(columns[c], spec.dtype_of(c), where) for c in spec.column_names}
        parts.setdefault(name, []).append((np.asarray(conn.times_ns, dtype=np.int64), cast))
    tables: dict[str, Table] = {}
    for name in (n for n in TOPICS if n in parts):
        chunks = parts[name]
        t_ns = np.concatenate([c[0] for c in chunks])
        columns = {k: np.concatenate([c[1][k] for c in chunks]) for k in chunks[0][1]}
        order = np.argsort(t_ns, kind="stable")
        tables[name] = Table(t_ns[order], {k: v[order] for k, v in columns.items()})
    return Recording(tables, skipped)


def _as_dtype(values: NDArray[Any], dtype: np.dtype[Any], where: str) -> NDArray[Any]:
    if values.dtype == dtype or dtype.kind == "O":
        return values
    if dtype.kind in "iu" and values.size:
        info = np.iinfo(dtype)
        if values.min() < info.min or values.max() > info.max:
            msg = f"{where}: values out of range for {dtype}"
            raise RecordingError(msg)
    return values.astype(dtype)
