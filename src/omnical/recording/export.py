"""Plain-text exports of a recording: CSV per topic, TUM trajectories.

CSV: one file per topic named after it (``/odom`` → ``odom.csv``, ``/omnical/events`` →
``omnical_events.csv``), header ``t_ns,<columns>``, floats written in Python's shortest
round-trip form so they parse back to the same numbers. An (N, k) column (a scan's ranges, a
JointState's positions) becomes k columns ``name.0`` … ``name.{k-1}``; REP 117 infinities are
written ``inf`` / ``-inf``, dropouts ``nan``. JointState topics of other names than
``/dead_wheels`` are named after their topic the same way.

TUM (``timestamp tx ty tz qx qy qz qw``, timestamp in seconds with all nine decimals of the
nanosecond bag time) for ``/odom``, ``/ground_truth`` (planar: z = 0, yaw as a quaternion about
z) and the vendor IPS positions ``/hedge_pos_ang`` (identity orientation, rows with flags bit 0
"coordinates unavailable" left out; one file per hedgehog address if there are several).
Existing files of the same names are replaced.

Pose topics of other names (motion capture: ``PoseStamped``, ``PoseWithCovarianceStamped``,
``Odometry``, ``TransformStamped``, tf; read by :mod:`omnical.recording.reference_topics`) are
written by :func:`export_poses_tum` and :func:`export_poses_csv`, planar like ``/odom``: TUM
with z = 0 and the yaw as a quaternion about z, CSV ``t_ns,x_m,y_m,yaw_rad`` (what
``--reference-file`` reads back). A file is named after the topic (``/mocap/pose`` →
``mocap_pose.tum``), a tf topic's per child frame (``/tf`` child ``base_link`` →
``tf_base_link.tum``).
"""

from __future__ import annotations

import csv
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from omnical.errors import RecordingError
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import GROUND_TRUTH, HEDGE_POS_ANG, ODOM

if TYPE_CHECKING:
    from collections.abc import Sequence

    from omnical.recording.reference_topics import PoseTopic

__all__ = [
    "export_csv",
    "export_poses_csv",
    "export_poses_tum",
    "pose_file_stem",
    "tum_timestamp",
]

_NS_PER_S = 1_000_000_000
_CSV_BATCH_ROWS = 20_000


def _stem(topic: str) -> str:
    return topic.strip("/").replace("/", "_") or "root"


def _out_dir(out_dir: str | Path) -> Path:
    path = Path(out_dir)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        msg = f"{path}: cannot create export directory: {err.strerror}"
        raise RecordingError(msg) from None
    return path


def _write_csv(path: Path, header: list[str], columns: list[NDArray[Any]], rows: int) -> Path:
    try:
        with path.open("w", newline="", encoding="utf-8") as stream:
            writer = csv.writer(stream)
            writer.writerow(header)
            # Python objects only for a batch of rows at a time: memory stays that of the
            # numpy table, however long the recording.
            for start in range(0, rows, _CSV_BATCH_ROWS):
                part = slice(start, start + _CSV_BATCH_ROWS)
                writer.writerows(zip(*(c[part].tolist() for c in columns), strict=True))
    except OSError as err:
        msg = f"{path}: cannot write CSV: {err.strerror}"
        raise RecordingError(msg) from None
    return path


def export_csv(recording: Recording, out_dir: str | Path) -> list[Path]:
    """Write one CSV per topic into ``out_dir`` (created if needed); return the files.

    Raises:
        RecordingError: A column has more than two dimensions, or a file cannot be written.
    """
    directory = _out_dir(out_dir)
    written: list[Path] = []
    for topic, table in recording.tables.items():
        header: list[str] = ["t_ns"]
        columns: list[NDArray[Any]] = [table.t_ns]
        for name in table.names:
            values = table[name]
            if values.ndim == 1:
                header.append(name)
                columns.append(values)
            elif values.ndim == 2:
                header.extend(f"{name}.{i}" for i in range(values.shape[1]))
                columns.extend(values[:, i] for i in range(values.shape[1]))
            else:
                msg = (
                    f"topic {topic}: column {name!r} has shape {values.shape}; CSV needs 1-D or 2-D"
                )
                raise RecordingError(msg)
        path = directory / f"{_stem(topic)}.csv"
        written.append(_write_csv(path, header, columns, len(table)))
    return written


def tum_timestamp(t_ns: int) -> str:
    """Nanoseconds as seconds with nine decimals, exactly (``1700000000.000000001``)."""
    sign = "-" if t_ns < 0 else ""
    sec, nsec = divmod(abs(int(t_ns)), _NS_PER_S)
    return f"{sign}{sec}.{nsec:09d}"


def _write_tum(path: Path, t_ns: NDArray[np.int64], rows: NDArray[np.float64]) -> Path:
    """``rows`` (N, 7): tx ty tz qx qy qz qw."""
    lines = [
        " ".join([tum_timestamp(t), *map(repr, row)])
        for t, row in zip(t_ns.tolist(), rows.tolist(), strict=True)
    ]
    try:
        path.write_text("".join(f"{line}\n" for line in lines), encoding="utf-8")
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


def export_tum(recording: Recording, out_dir: str | Path) -> list[Path]:
    """Write TUM trajectories of odometry, ground truth and IPS positions; return the files.

    Topics the recording lacks (or that have no valid row) produce no file.
    """
    directory = _out_dir(out_dir)
    written: list[Path] = []
    for topic in (ODOM, GROUND_TRUTH):
        if recording.has(topic):
            table = recording.topic(topic)
            path = directory / f"{_stem(topic)}.tum"
            written.append(_write_tum(path, table.t_ns, _planar_rows(table)))
    if recording.has(HEDGE_POS_ANG):
        table = recording.topic(HEDGE_POS_ANG)
        valid = table.take((table["flags"] & 1) == 0)
        addresses = np.unique(valid["address"]).tolist()
        for address in addresses:
            rows = valid.take(valid["address"] == address)
            n = len(rows)
            pose = np.column_stack(
                [rows["x_m"], rows["y_m"], rows["z_m"], np.zeros((n, 3)), np.ones(n)]
            ).astype(np.float64)
            name = _stem(HEDGE_POS_ANG) + (f"_{address}" if len(addresses) > 1 else "")
            written.append(_write_tum(directory / f"{name}.tum", rows.t_ns, pose))
    return written


def pose_file_stem(pose: PoseTopic) -> str:
    """The file name (without suffix) of a pose topic's export: the topic's, and for a tf topic
    the child frame's too (``/tf``, ``base_link`` → ``tf_base_link``)."""
    stem = _stem(pose.topic)
    if pose.msgtype == "tf2_msgs/msg/TFMessage" and pose.child_frame_id:
        stem += "_" + _stem(pose.child_frame_id)
    return stem


def export_poses_tum(poses: Sequence[PoseTopic], out_dir: str | Path) -> list[Path]:
    """Write each pose topic as a planar TUM trajectory (module docstring); return the files."""
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
