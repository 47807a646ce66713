"""Reference trajectories for ``omnical evaluate`` and ``calibrate estimate``: a file, a built-in
path, or the poses of a topic (motion capture).

* ``REF.csv`` with a header and columns ``t_s,x_m,y_m`` (seconds from the recording's first
  message, map frame) and optionally ``yaw_rad``; extra columns are ignored.
* ``REF.tum`` (or ``.txt``): the TUM RGB-D format (evo, ORB-SLAM): one pose per line,
  ``timestamp tx ty tz qx qy qz qw``, separated by spaces, ``#`` comments. A timestamp of 10⁸ s
  or more is absolute (the bag's clock, e.g. Unix time) and is taken relative to the
  recording's first message; smaller ones are already relative to it. Planar: x, y and the yaw
  of the quaternion about z.
* a pose topic of the bag (:func:`reference_from_poses`, read by
  :func:`omnical.recording.reference_topics.read_pose_topic`).
* ``lissajous`` (seed 000 Eq. 5, S = 1 m, trapezoidal phase profile), ``circle`` (1 m radius,
  seed 001) or ``square`` (1 m, seed 001): the reference starts when the recording's first
  non-zero ``/cmd_vel`` does; its position in the map is unknown, so evaluate it with
  ``--align se2`` (or ``origin``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omnical.errors import ConfigError, GeometryError, RecordingError
from omnical.evaluation.association import Trajectory
from omnical.recording.recording import Recording, Table
from omnical.trajectory.references import SEED001_SQUARE_M, Reference, circle, lissajous, polygon
from omnical.userfiles import read_text_file

__all__ = [
    "ABSOLUTE_TIME_S",
    "BUILTIN_REFERENCES",
    "TUM_SUFFIXES",
    "load_reference",
    "reference_from_poses",
]

BUILTIN_REFERENCES = ("lissajous", "circle", "square")
TUM_SUFFIXES = (".tum", ".txt")
"""File suffixes read as TUM trajectories (any other file is read as CSV)."""
ABSOLUTE_TIME_S = 1e8
"""A TUM timestamp at or beyond this (1973 in Unix time) is absolute, not from the recording's start."""


def _builtin(name: str) -> Reference:
    if name == "lissajous":
        return lissajous()
    if name == "circle":
        return circle()
    return polygon(SEED001_SQUARE_M)


def _motion_start_s(recording: Recording) -> float:
    if not recording.has("/cmd_vel"):
        msg = "a built-in reference starts with the first /cmd_vel command, and the recording has none"
        raise RecordingError(msg)
    cmd = recording.topic("/cmd_vel")
    moving = (np.abs(cmd["vx_mps"]) + np.abs(cmd["vy_mps"]) + np.abs(cmd["wz_radps"])) > 1e-9
    if not np.any(moving):
        msg = "the recording's /cmd_vel never commands any motion"
        raise RecordingError(msg)
    return float(cmd.t_s(recording.start_ns)[int(np.argmax(moving))])


_MAX_COORDINATE_M = 1e4
"""Largest |x|, |y| of a reference position: 10 km, far beyond any indoor positioning system."""
_MAX_TIME_S = 1e7
"""Largest |t| of a reference sample: about four months of recording."""


def _read_csv(path: Path) -> Trajectory:
    text = read_text_file(path, "reference CSV (t_s,x_m,y_m)")
    lines = [ln for ln in text.splitlines() if ln.strip()]
    if not lines:
        msg = f"{path}: empty reference file"
        raise ConfigError(msg)
    header = [h.strip() for h in lines[0].split(",")]
    missing = [c for c in ("t_s", "x_m", "y_m") if c not in header]
    if missing:
        msg = f"{path}: header needs columns t_s,x_m,y_m (missing {', '.join(missing)})"
        raise ConfigError(msg)
    names = ("t_s", "x_m", "y_m", "yaw_rad") if "yaw_rad" in header else ("t_s", "x_m", "y_m")
    cols = [header.index(c) for c in names]
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        fields = line.split(",")
        try:
            rows.append([float(fields[c]) for c in cols])
        except (ValueError, IndexError):
            msg = f"{path}: line {number}: expected numbers in columns {','.join(names)}, got {line.strip()!r}"
            raise ConfigError(msg) from None
    data = np.array(rows, dtype=np.float64).reshape(-1, len(names))
    if data.shape[0] < 2 or not np.all(np.isfinite(data)) or np.any(np.diff(data[:, 0]) <= 0):
        msg = f"{path}: need at least two rows of finite values with strictly increasing t_s"
        raise ConfigError(msg)
    far = np.flatnonzero(
        (np.abs(data[:, 0]) > _MAX_TIME_S)
        | np.any(np.abs(data[:, 1:3]) > _MAX_COORDINATE_M, axis=1)
    )
    if far.size:
        msg = (
            f"{path}: line {int(far[0]) + 2}: t_s must lie within ±{_MAX_TIME_S:.0e} s and x_m, "
            f"y_m within ±{_MAX_COORDINATE_M:.0e} m"
        )
        raise ConfigError(msg)
    yaw = data[:, 3] if data.shape[1] == 4 else None
    return Trajectory(data[:, 0], data[:, 1:3], yaw, "reference")


def _read_tum(path: Path, t0_ns: int) -> Trajectory:
    text = read_text_file(path, "TUM trajectory (timestamp tx ty tz qx qy qz qw)")
    rows: list[list[float]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        body = line.split("#", 1)[0].replace(",", " ").split()
        if not body:
            continue
        try:
            values = [float(v) for v in body]
        except ValueError:
            values = []
        if len(values) != 8:
            msg = (
                f"{path}: line {number}: a TUM line is 'timestamp tx ty tz qx qy qz qw' "
                f"(8 numbers), got {line.strip()!r}"
            )
            raise ConfigError(msg)
        rows.append(values)
    data = np.array(rows, dtype=np.float64).reshape(-1, 8)
    if data.shape[0] < 2 or not np.all(np.isfinite(data)):
        msg = f"{path}: need at least two poses of finite values"
        raise ConfigError(msg)
    stamps = data[:, 0]
    if stamps[0] >= ABSOLUTE_TIME_S:
        whole = np.floor(stamps[0])  # split off whole seconds: no precision lost to the epoch
        t_s = (stamps - whole) + (whole - t0_ns // 1_000_000_000) - (t0_ns % 1_000_000_000) / 1e9
    else:
        t_s = stamps
    if np.any(np.diff(t_s) <= 0):
        k = int(np.argmax(np.diff(t_s) <= 0)) + 1
        msg = f"{path}: timestamps must increase (pose {k + 1} is not after pose {k})"
        raise ConfigError(msg)
    if np.any(np.abs(data[:, 1:3]) > _MAX_COORDINATE_M) or np.any(np.abs(t_s) > _MAX_TIME_S):
        msg = (
            f"{path}: positions must lie within ±{_MAX_COORDINATE_M:.0e} m and times within "
            f"±{_MAX_TIME_S:.0e} s of the recording's start"
        )
        raise ConfigError(msg)
    qx, qy, qz, qw = data[:, 4], data[:, 5], data[:, 6], data[:, 7]
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    return Trajectory(np.asarray(t_s, dtype=np.float64), data[:, 1:3], yaw, "reference")


def reference_from_poses(table: Table, t0_ns: int) -> Trajectory:
    """The reference of a pose table (bag times; columns ``x_m``, ``y_m``, ``yaw_rad``), with
    times in seconds from ``t0_ns`` (the recording's first message).

    Raises:
        GeometryError: fewer than 2 poses.
    """
    if len(table) < 2:
        msg = f"a reference needs at least 2 poses, got {len(table)}"
        raise GeometryError(msg)
    xy = np.column_stack([table["x_m"], table["y_m"]]).astype(np.float64)
    return Trajectory(table.t_s(t0_ns), xy, np.asarray(table["yaw_rad"], np.float64), "reference")


def load_reference(spec: str, recording: Recording) -> Trajectory:
    """The reference named by ``spec``: a built-in name, a TUM or a CSV path (module docstring)."""
    if spec in BUILTIN_REFERENCES:
        ref = _builtin(spec)
        return Trajectory(
            ref.t_s + _motion_start_s(recording), ref.poses[:, :2], ref.poses[:, 2], "reference"
        )
    path = Path(spec)
    if path.suffix.lower() in TUM_SUFFIXES:
        return _read_tum(path, recording.start_ns)
    return _read_csv(path)
