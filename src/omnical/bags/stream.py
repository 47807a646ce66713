"""Reading chosen columns of a bag part by part: :func:`read_selected`.

The parts of :class:`~omnical.bags.bag.BagStream` are joined into growing buffers, so neither
the whole tables' decoding buffers nor the columns not kept are held.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from omnical.bags.bag import BagStream
from omnical.recording.recording import Recording, Table

__all__ = ["read_selected"]


class _Growing:
    """A topic's columns grown part by part in buffers doubled when full."""

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
    (every column of the others), read part by part through :class:`BagStream`.

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
