"""Incremental bag writing for long runs: flush as you go, keep everything on interruption.

:class:`BagRecorder` writes each batch as it comes, flushes every ``flush_period_s`` and keeps a
stopped run as ``RUN.partial`` (:attr:`~BagRecorder.kept_at`); a killed run: ``omnical recover``.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from types import TracebackType
from typing import Literal, Self

from numpy.typing import ArrayLike

from omnical.bags.bag import bag_location, bag_ros_version, check_target, put_in_place
from omnical.bags.sink import (
    DEFAULT_COMPRESSION,
    BagCompression,
    BagSink,
    chunk_compression,
    topic_spec,
)
from omnical.bags.staging import held_stops, make_staging, sweep_staging
from omnical.errors import RecordingError
from omnical.recording.recording import RecordingBuilder

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
        compression: Chunk compression, as for :func:`~omnical.bags.bag.write_bag` (each
            flushed chunk on its own, so :func:`recover_bag` still salvages it).
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
        self._closed_count = 0
        self._staging: Path | None = None
        self._last_flush = 0.0
        self.kept_at: Path | None = None
        """Where the closed bag went: ``path``, or a ``.partial`` name if the run was cut."""

    @property
    def writing_to(self) -> Path | None:
        """Where the bag is being written while open (in its staging directory), else None."""
        return self._sink.location if self._sink is not None else None

    @property
    def message_count(self) -> int:
        """Messages written so far."""
        return self._sink.message_count if self._sink is not None else self._closed_count

    def open(self) -> None:
        """Start the bag in its staging directory (an old bag stays until :meth:`close`)."""
        if self._sink is not None:
            msg = f"{self.path}: recorder is already open"
            raise RecordingError(msg)
        check_target(self.path, overwrite=self.overwrite)
        sweep_staging(self.path)
        staging = make_staging(self.path, "rec")
        sink = BagSink(staging / self.path.name, bag_ros_version(self.path), self.compression)
        try:
            sink.open()
        except BaseException:
            shutil.rmtree(staging, ignore_errors=True)
            raise
        self._sink, self._staging = sink, staging
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
        topic_spec(topic, self.path, tuple(columns))
        builder = RecordingBuilder()
        builder.add_many(topic, t_ns, **columns)
        sink.write_table(topic, builder.build().topic(topic))
        self._maybe_flush()

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self.flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Push everything written so far to disk."""
        self._open_sink().flush()
        self._last_flush = time.monotonic()

    def close(self, *, partial: bool = False) -> None:
        """Finish the bag (index, summary, metadata) and move it to its place.

        Args:
            partial: The run was cut short: keep the bag under a free ``.partial`` name
                beside ``path`` instead (the previous bag at ``path`` stays untouched).

        Raises:
            RecordingError: The bag cannot be finished (flushed chunks stay staged for
                ``omnical recover``), or the place was taken meanwhile (the bag is then kept
                under a ``.partial`` name, named in the message).
        """
        sink, self._sink = self._open_sink(), None
        self._closed_count = sink.message_count
        staging, self._staging = self._staging, None
        assert staging is not None
        try:
            sink.close()
        except RecordingError as err:  # the flushed chunks are on disk: say where, and how
            msg = f"{err}; what was flushed is kept in {staging}: `omnical recover {self.path}`"
            raise RecordingError(msg) from None
        with held_stops():  # a stop that comes now is raised once kept_at is set
            try:
                final = put_in_place(
                    sink.location, self.path, overwrite=self.overwrite, partial=partial
                )
            except RecordingError:
                shutil.rmtree(staging, ignore_errors=True)
                raise  # the place was taken meanwhile: the bag is kept as .partial, said there
            except OSError as err:
                msg = f"{self.path}: cannot move the finished recording into place "
                msg += f"({err.strerror}); it is kept in {sink.location}"
                raise RecordingError(msg) from None
            shutil.rmtree(staging, ignore_errors=True)
            self.kept_at = final

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
            self.close(partial=exc_type is not None)
        return False
