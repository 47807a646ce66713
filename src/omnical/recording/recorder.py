"""Incremental bag writing for long runs: flush as you go, keep everything on interruption.

rosbags cannot reopen an MCAP file to append, and its writers only index a bag on close, so
:class:`BagRecorder` keeps one writer open for the whole run and:

* writes each batch of rows straight into the bag (no copy of the run kept in memory);
* every ``flush_period_s`` of wall time (and on :meth:`BagRecorder.flush`) closes the chunk
  being filled and fsyncs it, so at most that much data is only in memory;
* closes the bag on leaving the ``with`` block, also on an exception or Ctrl-C, so an
  interrupted run leaves a complete, indexed bag;
* if the process dies without closing (``kill -9``, power loss), the bag has no index, but
  :func:`omnical.recording.recover.recover_bag` salvages every flushed chunk.

The bag goes where :func:`omnical.recording.bag.bag_location` says, like :func:`write_bag`.
"""

from __future__ import annotations

import time
from pathlib import Path
from types import TracebackType
from typing import Literal, Self

from numpy.typing import ArrayLike

from omnical.errors import RecordingError
from omnical.recording.bag import bag_location, bag_ros_version, check_target, remove_bag
from omnical.recording.recording import Recording, RecordingBuilder
from omnical.recording.sink import (
    DEFAULT_COMPRESSION,
    BagCompression,
    BagSink,
    chunk_compression,
    topic_spec,
)

__all__ = ["BagRecorder"]


class BagRecorder:
    """Context manager that writes rows of canonical topics to a bag as a run goes on.

    Example::

        with BagRecorder("run.mcap") as rec:
            rec.write_rows("/cmd_vel", t_ns, vx_mps=vx, vy_mps=vy, wz_radps=wz)

    Args:
        path: Output path (``.bag`` → ROS 1 file, else ROS 2 MCAP directory).
        overwrite: Replace an existing bag at the location.
        flush_period_s: Longest wall time between flushes to disk (0 flushes on every write).
        compression: Chunk compression, as for :func:`~omnical.recording.bag.write_bag`
            (default: zstd MCAP chunks for ROS 2, lz4 for ROS 1; None: uncompressed). Every
            flushed chunk is compressed on its own, so :func:`recover_bag` still salvages it.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        overwrite: bool = False,
        flush_period_s: float = 1.0,
        compression: BagCompression | None = DEFAULT_COMPRESSION,
    ) -> None:
        self.path = bag_location(path)
        self.compression = chunk_compression(compression, bag_ros_version(self.path), self.path)
        self.overwrite = overwrite
        self.flush_period_s = flush_period_s
        self._sink: BagSink | None = None
        self._last_flush = 0.0

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._sink.message_count if self._sink is not None else 0

    def open(self) -> None:
        """Create the bag (replacing an old one only if ``overwrite``)."""
        if self._sink is not None:
            msg = f"{self.path}: recorder is already open"
            raise RecordingError(msg)
        check_target(self.path, overwrite=self.overwrite)
        try:
            remove_bag(self.path)
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            msg = f"{self.path}: cannot create bag: {err.strerror}"
            raise RecordingError(msg) from None
        sink = BagSink(self.path, bag_ros_version(self.path), self.compression)
        sink.open()
        self._sink = sink
        self._last_flush = time.monotonic()

    def _open_sink(self) -> BagSink:
        if self._sink is None:
            msg = f"{self.path}: recorder is not open (use it in a with block)"
            raise RecordingError(msg)
        return self._sink

    def write_rows(self, topic: str, t_ns: ArrayLike, **columns: ArrayLike) -> None:
        """Write rows of a canonical topic: ``t_ns`` (N,) integer ns, columns (N,).

        Rows of one call are written sorted by time; calls may interleave topics freely.
        """
        sink = self._open_sink()
        topic_spec(topic, self.path)
        builder = RecordingBuilder()
        builder.add_many(topic, t_ns, **columns)
        sink.write_table(topic, builder.build().topic(topic))
        self._maybe_flush()

    def write_recording(self, recording: Recording) -> None:
        """Write every topic of ``recording``."""
        sink = self._open_sink()
        for topic, table in recording.tables.items():
            sink.write_table(topic, table)
        self._maybe_flush()

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Push everything written so far to disk."""
        self._open_sink().flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Finish the bag (index, summary, metadata)."""
        sink, self._sink = self._open_sink(), None
        sink.close()

    def __enter__(self) -> Self:
        self.open()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> Literal[False]:
        if self._sink is not None:
            self.close()
        return False
