"""References for ``omnical evaluate`` and ``calibrate estimate``: a file, a built-in path, a topic.

CSV (``t_s`` or ``t_ns``, ``x_m``, ``y_m``, ``yaw_rad``), TUM, a pose topic or ``lissajous``,
``circle``, ``square``; :class:`TimeBase` says how the times were read.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from decimal import Decimal, InvalidOperation
from enum import Enum
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError, GeometryError, RecordingError
from omnical.evaluation.association import Trajectory
from omnical.recording.recording import Recording, Table
from omnical.recording.topics import CMD_VEL
from omnical.trajectory.references import SEED001_SQUARE_M, Reference, circle, lissajous, polygon
from omnical.userfiles import read_text_file

__all__ = [
    "ABSOLUTE_TIME_S",
    "BUILTIN_REFERENCES",
    "OFF_PATH_M",
    "TUM_SUFFIXES",
    "LoadedReference",
    "TimeBase",
    "load_reference",
    "off_builtin_path",
    "read_reference",
    "reference_from_poses",
]

BUILTIN_REFERENCES = ("lissajous", "circle", "square")
TUM_SUFFIXES = (".tum", ".txt")
"""File suffixes read as TUM trajectories (any other file is read as CSV)."""
ABSOLUTE_TIME_S = 1e8
"""A time in seconds (CSV ``t_s``, TUM timestamp) at or beyond this (1973 in Unix time) is absolute
bag time, not seconds from the recording's start."""


def _builtin(name: str) -> Reference:
    if name == "lissajous":
        return lissajous()
    if name == "circle":
        return circle()
    return polygon(SEED001_SQUARE_M)


def _motion_start_s(recording: Recording) -> float:
    if not recording.has(CMD_VEL):
        msg = "a built-in reference starts with the first /cmd_vel command, and the recording has none"
        raise RecordingError(msg)
    cmd = recording.topic(CMD_VEL)
    moving = (np.abs(cmd["vx_mps"]) + np.abs(cmd["vy_mps"]) + np.abs(cmd["wz_radps"])) > 1e-9
    if not np.any(moving):
        msg = "the recording's /cmd_vel never commands any motion"
        raise RecordingError(msg)
    return float(cmd.t_s(recording.start_ns)[int(np.argmax(moving))])


_MAX_COORDINATE_M = 1e4
"""Largest |x|, |y| of a reference position: 10 km, far beyond any indoor positioning system."""
_MAX_TIME_S = 1e7
"""Largest |t| of a reference sample from the recording's first message: about four months."""
_QUATERNION_NORM_TOLERANCE = 0.01
"""Largest | ‖q‖ − 1 | of a TUM quaternion: a writer rounding to 3 digits stays well inside."""
_NS_PER_S = 1_000_000_000


class TimeBase(Enum):
    """How the times of a reference file were read (the rule in docs/DESIGN-NOTES.md)."""

    ABSOLUTE_NS = "absolute bag time (t_ns)"
    ABSOLUTE_S = "absolute bag time"
    RELATIVE_S = "relative to the bag start"
    MOTION_START = "from the first /cmd_vel motion"


@dataclass(frozen=True)
class LoadedReference:
    """A reference as read, and how its times were taken.

    Attributes:
        trajectory: times in seconds from the recording's first message.
        time_base: the rule applied to the file's times.
        time_column: what the times were called (``t_ns``, ``t_s``, ``timestamp``; ``""`` for
            a built-in path).
        motion_start_s: a built-in path's start (the first ``/cmd_vel`` motion), else 0.
    """

    trajectory: Trajectory
    time_base: TimeBase
    time_column: str = ""
    motion_start_s: float = 0.0

    def times_note(self, start_ns: int) -> str:
        """The rule applied, for one printed line (``start_ns``: the recording's first message)."""
        base = self.time_base
        if base is TimeBase.ABSOLUTE_NS:
            return f"reference times: {base.value}"
        if base is TimeBase.MOTION_START:
            return (
                f"reference times: {base.value} ({self.motion_start_s:.3f} s after the bag start)"
            )
        if base is TimeBase.ABSOLUTE_S:
            return f"reference times: {base.value} ({self.time_column} ≥ 1e8 s)"
        note = f"reference times: {base.value} ({self.time_column} < 1e8 s)"
        if start_ns < ABSOLUTE_TIME_S * _NS_PER_S:
            how = (
                "a t_ns column gives bag times"
                if self.time_column == "t_s"
                else f"subtract {start_ns / _NS_PER_S:.3f} s if they are bag times"
            )
            note += f"; the bag's clock starts at {start_ns / _NS_PER_S:.3f} s: {how}"
        return note


def _from_seconds(
    texts: list[str], stamps_s: NDArray[np.float64], t0_ns: int
) -> tuple[NDArray[np.float64], TimeBase]:
    """Seconds from ``t0_ns`` of file times in seconds (``texts`` as written, ``stamps_s`` as
    parsed): absolute if the first is ≥ 1e8 s, then taken from their text exactly."""
    if stamps_s[0] < ABSOLUTE_TIME_S:
        return stamps_s, TimeBase.RELATIVE_S
    t0 = Decimal(t0_ns).scaleb(-9)
    try:
        t_s = np.array([float(Decimal(x.strip()) - t0) for x in texts], dtype=np.float64)
    except (InvalidOperation, ValueError):  # a form float reads and Decimal not: float's value
        t_s = stamps_s - t0_ns / 1e9
    return t_s, TimeBase.ABSOLUTE_S


def _int_ns(text: str) -> int:
    """A nanosecond time field: an integer (exact), or a number of whole nanoseconds."""
    try:
        return int(text)
    except ValueError:
        value = float(text)  # ValueError goes to the caller
        if not math.isfinite(value) or abs(value) > 2.0**62:
            raise ValueError(text) from None
        return round(value)


def _read_csv(path: Path, t0_ns: int) -> LoadedReference:
    text = read_text_file(path, "reference CSV (t_s or t_ns, x_m, y_m)")
    numbered = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    if not numbered:
        msg = f"{path}: empty reference file"
        raise ConfigError(msg)
    lines = [ln for _, ln in numbered]
    header = [h.strip() for h in lines[0].split(",")]
    time_name = "t_ns" if "t_ns" in header else "t_s"
    missing = [c for c in (time_name, "x_m", "y_m") if c not in header]
    if missing:
        msg = f"{path}: header needs columns t_s (or t_ns),x_m,y_m (missing {', '.join(missing)})"
        raise ConfigError(msg)
    names = ("x_m", "y_m", "yaw_rad") if "yaw_rad" in header else ("x_m", "y_m")
    t_col, cols = header.index(time_name), [header.index(c) for c in names]
    stamps: list[float] = []
    texts: list[str] = []
    stamps_ns: list[int] = []
    rows = []
    for number, line in numbered[1:]:
        fields = line.split(",")
        try:
            if time_name == "t_ns":
                stamps_ns.append(_int_ns(fields[t_col].strip()))
            else:
                stamps.append(float(fields[t_col]))
                texts.append(fields[t_col])
            rows.append([float(fields[c]) for c in cols])
        except (ValueError, IndexError):
            wanted = ",".join((time_name, *names))
            msg = (
                f"{path}: line {number}: expected numbers in columns {wanted}, got {line.strip()!r}"
            )
            raise ConfigError(msg) from None
    data = np.array(rows, dtype=np.float64).reshape(-1, len(names))
    if time_name == "t_ns":
        t_ns = np.array(stamps_ns, dtype=np.int64)
        t_s = (t_ns - np.int64(t0_ns)).astype(np.float64) / 1e9
        base = TimeBase.ABSOLUTE_NS
    else:
        raw = np.array(stamps, dtype=np.float64)
        finite = raw.size > 0 and bool(np.all(np.isfinite(raw)))
        t_s, base = _from_seconds(texts, raw, t0_ns) if finite else (raw, TimeBase.RELATIVE_S)
    line_of = [n for n, _ in numbered[1:]]
    bad = np.argwhere(~np.isfinite(data))
    if bad.size:
        row, col = (int(v) for v in bad[0])
        msg = f"{path}: line {line_of[row]}: {names[col]}: not a finite number ({data[row, col]})"
        raise ConfigError(msg)
    times = t_ns if time_name == "t_ns" else t_s  # integers compared exactly
    if not np.all(np.isfinite(times)):
        row = int(np.flatnonzero(~np.isfinite(times))[0])
        msg = f"{path}: line {line_of[row]}: {time_name}: not a finite number ({times[row]})"
        raise ConfigError(msg)
    if data.shape[0] < 2:
        msg = f"{path}: need at least two rows (t_s or t_ns, x_m, y_m)"
        raise ConfigError(msg)
    if not np.all(np.diff(times) > 0):
        row = int(np.flatnonzero(~(np.diff(times) > 0))[0]) + 1
        msg = f"{path}: line {line_of[row]}: {time_name} does not increase from the line before"
        raise ConfigError(msg)
    far = np.flatnonzero(
        (np.abs(t_s) > _MAX_TIME_S) | np.any(np.abs(data[:, :2]) > _MAX_COORDINATE_M, axis=1)
    )
    if far.size:
        msg = (
            f"{path}: line {line_of[int(far[0])]}: {time_name} must lie within ±{_MAX_TIME_S:.0e} s "
            f"of the bag start ({base.value}) and x_m, y_m within ±{_MAX_COORDINATE_M:.0e} m"
        )
        raise ConfigError(msg)
    yaw = data[:, 2] if data.shape[1] == 3 else None
    trajectory = Trajectory(np.asarray(t_s, np.float64), data[:, :2], yaw, "reference")
    return LoadedReference(trajectory, base, time_name)


def _read_tum(path: Path, t0_ns: int) -> LoadedReference:
    text = read_text_file(path, "TUM trajectory (timestamp tx ty tz qx qy qz qw)")
    rows: list[list[float]] = []
    texts: list[str] = []
    numbers: list[int] = []
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
        if not all(math.isfinite(v) for v in values):
            msg = f"{path}: line {number}: need finite numbers, got {line.strip()!r}"
            raise ConfigError(msg)
        rows.append(values)
        texts.append(body[0])
        numbers.append(number)
    data = np.array(rows, dtype=np.float64).reshape(-1, 8)
    if data.shape[0] < 2:
        msg = f"{path}: need at least two poses of finite values"
        raise ConfigError(msg)
    t_s, base = _from_seconds(texts, data[:, 0], t0_ns)
    if np.any(np.diff(t_s) <= 0):
        k = int(np.argmax(np.diff(t_s) <= 0)) + 1
        msg = f"{path}: timestamps must increase (pose {k + 1} is not after pose {k})"
        raise ConfigError(msg)
    if np.any(np.abs(data[:, 1:3]) > _MAX_COORDINATE_M) or np.any(np.abs(t_s) > _MAX_TIME_S):
        msg = (
            f"{path}: positions must lie within ±{_MAX_COORDINATE_M:.0e} m and times within "
            f"±{_MAX_TIME_S:.0e} s of the recording's start ({base.value})"
        )
        raise ConfigError(msg)
    qx, qy, qz, qw = _unit_quaternions(path, data[:, 4:8], numbers)
    yaw = np.arctan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    trajectory = Trajectory(t_s, data[:, 1:3], yaw, "reference")
    return LoadedReference(trajectory, base, "timestamps")


def _unit_quaternions(
    path: Path, quaternions: NDArray[np.float64], numbers: list[int]
) -> NDArray[np.float64]:
    """(4, N) qx, qy, qz, qw of (N, 4) TUM quaternions, normalised: each must be a unit
    quaternion within :data:`_QUATERNION_NORM_TOLERANCE` (an all-zero one has no yaw at all).

    Raises:
        ConfigError: ``path: line N: ...`` naming the first quaternion that is not.
    """
    inside = np.max(np.abs(quaternions), axis=1) <= 2.0  # beyond: far from unit (no overflow)
    norms = np.where(inside, np.linalg.norm(np.clip(quaternions, -2.0, 2.0), axis=1), np.inf)
    bad = np.flatnonzero(np.abs(norms - 1.0) > _QUATERNION_NORM_TOLERANCE)
    if bad.size:
        k = int(bad[0])
        what = f"norm {norms[k]:.6g}" if inside[k] else "a component beyond ±1"
        if norms[k] == 0.0:
            what = "all zero: no orientation"
        msg = f"{path}: line {numbers[k]}: qx qy qz qw must be a unit quaternion ({what})"
        raise ConfigError(msg)
    unit: NDArray[np.float64] = (quaternions / norms[:, None]).T
    return unit


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


def read_reference(spec: str, recording: Recording) -> LoadedReference:
    """The reference named by ``spec`` (a built-in name, a TUM or a CSV path; docs/DESIGN-NOTES.md)
    and the rule its times were read by.

    Raises:
        ConfigError: a malformed file, times or positions out of any room.
        RecordingError: a built-in path and a recording without ``/cmd_vel`` motion.
    """
    if spec in BUILTIN_REFERENCES:
        ref = _builtin(spec)
        start_s = _motion_start_s(recording)
        trajectory = Trajectory(ref.t_s + start_s, ref.poses[:, :2], ref.poses[:, 2], "reference")
        return LoadedReference(trajectory, TimeBase.MOTION_START, "", start_s)
    path = Path(spec)
    if path.suffix.lower() in TUM_SUFFIXES:
        return _read_tum(path, recording.start_ns)
    return _read_csv(path, recording.start_ns)


def load_reference(spec: str, recording: Recording) -> Trajectory:
    """The reference named by ``spec``: a built-in name, a TUM or a CSV path."""
    return read_reference(spec, recording).trajectory


OFF_PATH_M = 0.25
"""A built-in reference farther than this (RMS, m) from every aligned estimate is not the path driven."""


def off_builtin_path(reference: str, align: str, rmse_m: Mapping[str, float]) -> str | None:
    """Why the estimates' RMS errors (``rmse_m`` by estimate) against the built-in ``reference``
    say the recording does not follow that path, or None."""
    if reference not in BUILTIN_REFERENCES or align == "none" or not rmse_m:
        return None
    name, best = min(rmse_m.items(), key=lambda item: item[1])
    if not best > OFF_PATH_M:
        return None
    return (
        f"--reference {reference}: the recording does not follow the built-in {reference} "
        f"path: its closest estimate ({name}) is {best:.2f} m RMS from it after "
        f"{align} alignment (a run of the path is within about 0.1 m); give the path it "
        "drove with --reference-file or --reference-topic"
    )
