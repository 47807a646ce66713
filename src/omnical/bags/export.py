"""Plain-text exports of a recording: CSV per topic, TUM trajectories.

:func:`export_bag_csv` and :func:`export_bag_tum` stream a bag part by part into files named after
its topics, in place once complete; :func:`export_poses_tum` / ``_csv`` for other pose topics.
"""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np
from numpy.typing import NDArray

from omnical.bags.bag import STREAM_BATCH, BagStream
from omnical.bags.staging import make_parents
from omnical.errors import RecordingError
from omnical.recording.recording import Table
from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM

if TYPE_CHECKING:
    from collections.abc import Collection, Mapping, Sequence

    from omnical.bags.reference_topics import PoseTopic

__all__ = [
    "BagExport",
    "csv_rows",
    "export_bag_csv",
    "export_bag_tum",
    "export_poses_csv",
    "export_poses_tum",
    "pose_file_stem",
    "tum_lines",
    "tum_timestamp",
]

_NS_PER_S = 1_000_000_000
_CSV_BATCH_ROWS = 20_000
_TUM_TOPICS = (ODOM, GROUND_TRUTH, HEDGE_POS_ANG)


def _stem(topic: str) -> str:
    return topic.strip("/").replace("/", "_") or "root"


def _out_dir(out_dir: str | Path) -> Path:
    path = Path(out_dir)
    try:
        make_parents(path)
    except OSError as err:
        msg = f"{path}: cannot create export directory: {err.strerror}"
        raise RecordingError(msg) from None
    return path


def csv_rows(columns: Sequence[NDArray[Any]]) -> str:
    """Rows of 1-D ``columns`` (equal lengths) as :func:`csv.writer` writes them (``\\r\\n``).

    Numbers are formatted a column at a time (``repr``, what csv.writer writes); rows with a
    text column go through :func:`csv.writer` itself, for its quoting.
    """
    if not columns or not len(columns[0]):
        return ""
    if any(c.dtype.kind not in "biuf" for c in columns):
        text = io.StringIO()
        csv.writer(text).writerows(zip(*(c.tolist() for c in columns), strict=True))
        return text.getvalue()
    fields = [list(map(repr, c.tolist())) for c in columns]  # repr == str of int, float
    return "\r\n".join(map(",".join, zip(*fields, strict=True))) + "\r\n"


def _csv_layout(topic: str, table: Table) -> tuple[list[str], list[str]]:
    """The header of ``topic``'s CSV and the column of ``table`` each value column comes from."""
    header: list[str] = ["t_ns"]
    for name in table.names:
        values = table[name]
        if values.ndim == 1:
            header.append(name)
        elif values.ndim == 2:
            header.extend(f"{name}.{i}" for i in range(values.shape[1]))
        else:
            msg = f"topic {topic}: column {name!r} has shape {values.shape}; CSV needs 1-D or 2-D"
            raise RecordingError(msg)
    return header, list(table.names)


def _csv_columns(table: Table, start: int = 0, stop: int | None = None) -> list[NDArray[Any]]:
    """``t_ns`` and every column of rows ``start:stop`` of ``table``, 2-D ones split."""
    part = slice(start, stop)
    columns: list[NDArray[Any]] = [table.t_ns[part]]
    for name in table.names:
        values = table[name][part]
        columns.extend([values] if values.ndim == 1 else list(values.T))
    return columns


_PARTIAL = ".omnical-partial-"


def _sweep_partial(directory: Path) -> None:
    """Delete the hidden files a killed export left in ``directory`` (:class:`_StagedFile`)."""
    for stale in directory.glob(f".*{_PARTIAL}*"):
        stale.unlink(missing_ok=True)


class _StagedFile:
    """A file written under a hidden name beside ``path``; :meth:`commit` gives it its name.

    A failed export leaves the name as it was; a killed one a hidden ``.NAME.omnical-partial-K``.
    """

    def __init__(self, path: Path, key: int, what: str) -> None:
        self.path = path
        self.what = what
        self.staged = path.with_name(f".{path.name}{_PARTIAL}{key}")
        self.rows = 0
        try:
            self.stream: TextIO | None = self.staged.open("w", newline="", encoding="utf-8")
        except OSError as err:
            raise self._error(err) from None

    def _error(self, err: OSError) -> RecordingError:
        return RecordingError(f"{self.path}: cannot write {self.what}: {err.strerror or err}")

    def write(self, text: str, rows: int) -> None:
        assert self.stream is not None
        try:
            self.stream.write(text)
        except OSError as err:
            raise self._error(err) from None
        self.rows += rows

    def commit(self) -> Path:
        """Close the file and move it to its name (replacing a file there)."""
        assert self.stream is not None
        try:
            self.stream.close()
            self.stream = None
            self.staged.replace(self.path)
        except OSError as err:
            raise self._error(err) from None
        return self.path

    def discard(self) -> None:
        """Close and delete the staged file (errors ignored: nothing under the name changed)."""
        if self.stream is not None:
            self.stream.close()
            self.stream = None
        self.staged.unlink(missing_ok=True)


def _write_csv(path: Path, header: list[str], columns: list[NDArray[Any]], rows: int) -> Path:
    try:
        with path.open("w", newline="", encoding="utf-8") as stream:
            csv.writer(stream).writerow(header)
            # rows formatted a batch at a time: memory stays that of the numpy table
            for start in range(0, rows, _CSV_BATCH_ROWS):
                stream.write(csv_rows([c[start : start + _CSV_BATCH_ROWS] for c in columns]))
    except OSError as err:
        msg = f"{path}: cannot write CSV: {err.strerror}"
        raise RecordingError(msg) from None
    return path


@dataclass(frozen=True)
class BagExport:
    """What :func:`export_bag_csv` or :func:`export_bag_tum` did.

    Attributes:
        written: the files: CSV in the order of ``read_bag``'s tables; TUM odometry, ground
            truth, then each hedgehog by address.
        notes: what reading cleaned (:attr:`Recording.notes` of ``read_bag``).
        topics: the topics read that hold at least one row (:meth:`Recording.has`).
        bag_topics: every topic of the bag → its type (as
            :func:`~omnical.bags.reference_topics.bag_topics` lists them).
    """

    written: tuple[Path, ...]
    notes: tuple[str, ...]
    topics: frozenset[str]
    bag_topics: Mapping[str, str]


class _CsvTopic:
    """One topic's CSV, written part by part."""

    def __init__(self, path: Path, key: int, topic: str, table: Table) -> None:
        self.header, self.names = _csv_layout(topic, table)
        self.file = _StagedFile(path, key, "CSV")
        text = io.StringIO()
        csv.writer(text).writerow(self.header)
        self.file.write(text.getvalue(), 0)

    def append(self, table: Table) -> None:
        for start in range(0, len(table), _CSV_BATCH_ROWS):
            stop = start + _CSV_BATCH_ROWS
            columns = _csv_columns(table, start, stop)
            self.file.write(csv_rows(columns), len(columns[0]))


def export_bag_csv(
    source: str | Path,
    out_dir: str | Path,
    topics: Collection[str] | None = None,
    *,
    batch: int = STREAM_BATCH,
) -> BagExport:
    """Stream the topics omnical reads from bag ``source`` into one CSV each in ``out_dir``.

    Each file holds the rows of ``read_bag(source, topics)``'s table (format:
    docs/DESIGN-NOTES.md); none if the topics hold no row at all.

    Raises:
        RecordingError: The bag cannot be read (as ``read_bag``), a column has more than two
            dimensions, or a file cannot be written. Files already there are left as they were.
    """
    stream = BagStream(source, topics, batch=batch)
    directory = _out_dir(out_dir)
    _sweep_partial(directory)
    files: dict[str, _CsvTopic] = {}
    try:
        for part in stream.parts():
            current = files.get(part.topic)
            if current is None or part.first:
                if current is not None:
                    current.file.discard()
                path = directory / f"{_stem(part.topic)}.csv"
                current = files[part.topic] = _CsvTopic(path, len(files), part.topic, part.table)
            current.append(part.table)
        with_rows = frozenset(t for t, f in files.items() if f.file.rows)
        written = (
            tuple(files[t].file.commit() for t in stream.topics if t in files) if with_rows else ()
        )
    finally:
        for current in files.values():
            current.file.discard()
    return BagExport(written, stream.notes, with_rows, stream.bag_topics)


def tum_timestamp(t_ns: int) -> str:
    """Nanoseconds as seconds with nine decimals, exactly (``1700000000.000000001``)."""
    sign = "-" if t_ns < 0 else ""
    sec, nsec = divmod(abs(int(t_ns)), _NS_PER_S)
    return f"{sign}{sec}.{nsec:09d}"


def tum_lines(t_ns: NDArray[np.int64], rows: NDArray[np.float64]) -> str:
    """TUM lines of ``t_ns`` (N,) and ``rows`` (N, 7): tx ty tz qx qy qz qw, ``repr`` floats."""
    if not len(t_ns):
        return ""
    times = np.asarray(t_ns, dtype=np.int64)
    if int(times.min()) < 0:
        stamps = [tum_timestamp(t) for t in times.tolist()]
    else:
        sec, nsec = np.divmod(times, _NS_PER_S)
        stamps = list(map("{}.{:09d}".format, sec.tolist(), nsec.tolist()))
    fields = [stamps, *(list(map(repr, rows[:, k].tolist())) for k in range(rows.shape[1]))]
    return "\n".join(map(" ".join, zip(*fields, strict=True))) + "\n"


def _write_tum(path: Path, t_ns: NDArray[np.int64], rows: NDArray[np.float64]) -> Path:
    """``rows`` (N, 7): tx ty tz qx qy qz qw."""
    try:
        path.write_text(tum_lines(t_ns, rows), encoding="utf-8")
    except OSError as err:
        msg = f"{path}: cannot write TUM file: {err.strerror}"
        raise RecordingError(msg) from None
    return path


def _planar_rows(table: Table) -> NDArray[np.float64]:
    n = len(table)
    half: NDArray[Any] = 0.5 * table["yaw_rad"]
    zero = np.zeros(n)
    return np.column_stack(
        [table["x_m"], table["y_m"], zero, zero, zero, np.sin(half), np.cos(half)]
    ).astype(np.float64)


def _hedge_rows(table: Table) -> tuple[NDArray[np.int64], NDArray[Any], NDArray[np.float64]]:
    """Times, addresses and TUM rows of the valid IPS positions of ``table``."""
    valid = table.take((table["flags"] & 1) == 0)
    n = len(valid)
    pose = np.column_stack(
        [valid["x_m"], valid["y_m"], valid["z_m"], np.zeros((n, 3)), np.ones(n)]
    ).astype(np.float64)
    return valid.t_ns, valid["address"], pose


def export_bag_tum(
    source: str | Path, out_dir: str | Path, *, batch: int = STREAM_BATCH
) -> BagExport:
    """Stream odometry, ground truth and IPS positions of bag ``source`` into TUM files.

    A planar trajectory each for odometry and ground truth, and the valid fixes of each
    hedgehog (one file per address when there are several); format: docs/DESIGN-NOTES.md.

    Raises:
        RecordingError: The bag cannot be read (as ``read_bag``) or a file cannot be written.
            Files already there are left as they were.
    """
    stream = BagStream(source, _TUM_TOPICS, batch=batch)
    directory = _out_dir(out_dir)
    _sweep_partial(directory)
    files: dict[tuple[str, int], _StagedFile] = {}
    counts: dict[str, int] = {}
    stems = {ODOM: _stem(ODOM), GROUND_TRUTH: _stem(GROUND_TRUTH)}

    def file(topic: str, address: int) -> _StagedFile:
        key = (topic, address)
        if key not in files:
            name = stems.get(topic, f"{_stem(topic)}_{address}")
            files[key] = _StagedFile(directory / f"{name}.tum", len(files), "TUM file")
        return files[key]

    try:
        for part in stream.parts():
            table = part.table
            if part.first:
                for key in [k for k in files if k[0] == part.topic]:
                    files.pop(key).discard()
                counts[part.topic] = 0
            counts[part.topic] += len(table)
            if not len(table):
                continue
            if part.topic != HEDGE_POS_ANG:
                file(part.topic, 0).write(tum_lines(table.t_ns, _planar_rows(table)), len(table))
                continue
            t_ns, addresses, pose = _hedge_rows(table)
            for address in np.unique(addresses).tolist():
                mine = addresses == address
                file(HEDGE_POS_ANG, address).write(
                    tum_lines(t_ns[mine], pose[mine]), int(np.count_nonzero(mine))
                )
        with_rows = frozenset(t for t, n in counts.items() if n)
        written: list[Path] = []
        if with_rows:
            for topic in (ODOM, GROUND_TRUTH):
                if (topic, 0) in files:
                    written.append(files[topic, 0].commit())
            hedgehogs = sorted(a for t, a in files if t == HEDGE_POS_ANG)
            for address in hedgehogs:
                staged = files[HEDGE_POS_ANG, address]
                if len(hedgehogs) == 1:
                    staged.path = directory / f"{_stem(HEDGE_POS_ANG)}.tum"
                written.append(staged.commit())
    finally:
        for staged in files.values():
            staged.discard()
    return BagExport(tuple(written), stream.notes, with_rows, stream.bag_topics)


def pose_file_stem(pose: PoseTopic) -> str:
    """The file name (without suffix) of a pose topic's export: the topic's, and for a tf topic
    the child frame's too (``/tf``, ``base_link`` → ``tf_base_link``)."""
    stem = _stem(pose.topic)
    if pose.msgtype == "tf2_msgs/msg/TFMessage" and pose.child_frame_id:
        stem += "_" + _stem(pose.child_frame_id)
    return stem


def export_poses_tum(poses: Sequence[PoseTopic], out_dir: str | Path) -> list[Path]:
    """Write each pose topic as a planar TUM trajectory (docs/DESIGN-NOTES.md); return the files."""
    directory = _out_dir(out_dir)
    return [
        _write_tum(directory / f"{pose_file_stem(p)}.tum", p.table.t_ns, _planar_rows(p.table))
        for p in poses
    ]


def export_poses_csv(poses: Sequence[PoseTopic], out_dir: str | Path) -> list[Path]:
    """Write each pose topic as CSV ``t_ns,x_m,y_m,yaw_rad``; return the files."""
    directory = _out_dir(out_dir)
    written = []
    for pose in poses:
        names = ["x_m", "y_m", "yaw_rad"]
        columns: list[NDArray[Any]] = [pose.table.t_ns, *(pose.table[n] for n in names)]
        path = directory / f"{pose_file_stem(pose)}.csv"
        written.append(_write_csv(path, ["t_ns", *names], columns, len(pose.table)))
    return written
