"""Reference trajectories for ``omnical evaluate``: a CSV file or a built-in path.

* ``REF.csv`` with a header and columns ``t_s,x_m,y_m`` (seconds from the recording's first
  message, map frame); extra columns are ignored.
* ``lissajous`` (seed 000 Eq. 5, S = 1 m, trapezoidal phase profile), ``circle`` (1 m radius,
  seed 001) or ``square`` (1 m, seed 001): the reference starts when the recording's first
  non-zero ``/cmd_vel`` does; its position in the map is unknown, so evaluate it with
  ``--align se2`` (or ``origin``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from omnical.errors import ConfigError, RecordingError
from omnical.evaluation.association import Trajectory
from omnical.recording.recording import Recording
from omnical.trajectory.references import SEED001_SQUARE_M, Reference, circle, lissajous, polygon
from omnical.userfiles import read_text_file

__all__ = ["BUILTIN_REFERENCES", "load_reference"]

BUILTIN_REFERENCES = ("lissajous", "circle", "square")


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
    cols = [header.index(c) for c in ("t_s", "x_m", "y_m")]
    rows = []
    for number, line in enumerate(lines[1:], start=2):
        fields = line.split(",")
        try:
            rows.append([float(fields[c]) for c in cols])
        except (ValueError, IndexError):
            msg = f"{path}: line {number}: expected numbers in columns t_s,x_m,y_m, got {line.strip()!r}"
            raise ConfigError(msg) from None
    data = np.array(rows, dtype=np.float64).reshape(-1, 3)
    if data.shape[0] < 2 or not np.all(np.isfinite(data)) or np.any(np.diff(data[:, 0]) <= 0):
        msg = f"{path}: need at least two rows of finite values with strictly increasing t_s"
        raise ConfigError(msg)
    far = np.flatnonzero(
        (np.abs(data[:, 0]) > _MAX_TIME_S) | np.any(np.abs(data[:, 1:]) > _MAX_COORDINATE_M, axis=1)
    )
    if far.size:
        msg = (
            f"{path}: line {int(far[0]) + 2}: t_s must lie within ±{_MAX_TIME_S:.0e} s and x_m, "
            f"y_m within ±{_MAX_COORDINATE_M:.0e} m"
        )
        raise ConfigError(msg)
    return Trajectory(data[:, 0], data[:, 1:], None, "reference")


def load_reference(spec: str, recording: Recording) -> Trajectory:
    """The reference named by ``spec``: a built-in name or a CSV path (module docstring)."""
    if spec in BUILTIN_REFERENCES:
        ref = _builtin(spec)
        return Trajectory(
            ref.t_s + _motion_start_s(recording), ref.poses[:, :2], ref.poses[:, 2], "reference"
        )
    return _read_csv(Path(spec))
