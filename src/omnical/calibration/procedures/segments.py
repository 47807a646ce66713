"""Segmentation of a run from the commanded twist (``/cmd_vel``) alone.

:func:`segment_commands` cuts a run into ``still`` segments and moves, each move classed over its
whole extent (``forward``, ``left``, ``rotate_ccw``, … or ``mixed``).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import CalibrationError

__all__ = ["Segment", "SegmentKind", "segment_commands", "segment_mask", "settled"]

SegmentKind = Literal[
    "still", "forward", "reverse", "left", "right", "rotate_ccw", "rotate_cw", "mixed"
]
"""Kinds of segment: forward/reverse (±vx), left/right (±vy), rotate_ccw/rotate_cw (±wz)."""

_Array = NDArray[np.float64]
_KINDS: tuple[tuple[SegmentKind, SegmentKind], ...] = (
    ("forward", "reverse"),
    ("left", "right"),
    ("rotate_ccw", "rotate_cw"),
)


@dataclass(frozen=True)
class Segment:
    """A stand-still or a move of a run, found from the commanded twist.

    Attributes:
        kind: what the command does over the segment.
        t_start_s: time the segment starts (the command leaves zero, or becomes zero for
            ``still``), in the time base of the command samples.
        t_end_s: time the segment ends (the command is back to zero, or leaves zero).
        direction: +1 for forward, left and rotate_ccw, −1 for reverse, right and rotate_cw,
            0 for still and mixed.
        commanded_integral: (∫vx dt in m, ∫vy dt in m, ∫wz dt in rad) of the command over the
            segment, zero-order hold: the commanded distance or angle of a pure move.
        truncated_start: the segment starts at the recording's first sample (it may have
            begun before).
        truncated_end: the segment ends at the recording's last sample.
    """

    kind: SegmentKind
    t_start_s: float
    t_end_s: float
    direction: int
    commanded_integral: tuple[float, float, float] = (0.0, 0.0, 0.0)
    truncated_start: bool = False
    truncated_end: bool = False

    @property
    def duration_s(self) -> float:
        """Length of the segment in s."""
        return self.t_end_s - self.t_start_s


def _check_commands(
    t_s: ArrayLike, vx_mps: ArrayLike, vy_mps: ArrayLike, wz_radps: ArrayLike
) -> tuple[_Array, _Array]:
    arrays = [np.asarray(a, dtype=np.float64) for a in (t_s, vx_mps, vy_mps, wz_radps)]
    shapes = {a.shape for a in arrays}
    if len(shapes) != 1 or arrays[0].ndim != 1:
        msg = f"t_s, vx_mps, vy_mps, wz_radps must be (N,) arrays of one length, got {shapes}"
        raise CalibrationError(msg)
    t = arrays[0]
    twist = np.column_stack(arrays[1:]) if len(t) else np.zeros((0, 3))
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(twist))):
        msg = "the commanded twist contains non-finite values"
        raise CalibrationError(msg)
    if np.any(np.diff(t) < 0.0):
        msg = "t_s must be non-decreasing"
        raise CalibrationError(msg)
    return t, twist


def _runs(moving: NDArray[np.bool_]) -> list[tuple[int, int, bool]]:
    """Maximal runs (first index, last index, moving) of equal values."""
    edges = np.flatnonzero(np.diff(moving.astype(np.int8))) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges - 1, [len(moving) - 1]])
    return [(int(i), int(j), bool(moving[i])) for i, j in zip(starts, ends, strict=True)]


def _classify(twist: _Array, dt: _Array, lever_m: float, ratio: float) -> tuple[SegmentKind, int]:
    """Kind and direction of a move from its samples (N, 3) and their hold times (N,)."""
    lever = np.array([1.0, 1.0, lever_m])
    if not np.any(dt > 0.0):  # a single sample, or samples sharing one time stamp
        dt = np.ones_like(dt)
    magnitude = (np.abs(twist) * lever * dt[:, None]).sum(axis=0)
    signed = (twist * lever * dt[:, None]).sum(axis=0)
    axis = int(np.argmax(magnitude))
    top = float(magnitude[axis])
    others = np.delete(magnitude, axis)
    if top <= 0.0 or np.any(others > ratio * top) or abs(signed[axis]) < (1.0 - ratio) * top:
        return "mixed", 0
    positive, negative = _KINDS[axis]
    return (positive, 1) if signed[axis] > 0.0 else (negative, -1)


def segment_commands(
    t_s: ArrayLike,
    vx_mps: ArrayLike,
    vy_mps: ArrayLike,
    wz_radps: ArrayLike,
    *,
    min_still_s: float = 1.0,
    linear_tol_mps: float = 2e-3,
    angular_tol_radps: float = 5e-3,
    mixed_ratio: float = 0.2,
    yaw_lever_m: float = 0.3,
) -> list[Segment]:
    """Cut a run into stand-stills and moves from its commanded body twist.

    Args:
        t_s: (N,) command times in s, non-decreasing.
        vx_mps: (N,) commanded forward speed in m/s.
        vy_mps: (N,) commanded leftward speed in m/s.
        wz_radps: (N,) commanded yaw rate in rad/s, counter-clockwise positive.
        min_still_s: shortest pause that counts as a stand-still.
        linear_tol_mps: |vx|, |vy| up to this count as zero (command noise).
        angular_tol_radps: |wz| up to this counts as zero.
        mixed_ratio: how much of the other components a pure move may carry
            (docs/DESIGN-NOTES.md), in [0, 0.5).
        yaw_lever_m: lever arm in m that turns a yaw rate into a speed to compare it with the
            translation.

    Returns:
        The segments in time order, not overlapping; empty for an empty input.

    Raises:
        CalibrationError: arrays of different shapes, non-finite values, decreasing times or
            invalid options.
    """
    if min_still_s < 0.0 or linear_tol_mps < 0.0 or angular_tol_radps < 0.0:
        msg = "min_still_s, linear_tol_mps and angular_tol_radps must be ≥ 0"
        raise CalibrationError(msg)
    if not 0.0 <= mixed_ratio < 0.5 or not yaw_lever_m > 0.0:
        msg = f"need 0 ≤ mixed_ratio < 0.5 and yaw_lever_m > 0, got {mixed_ratio}, {yaw_lever_m}"
        raise CalibrationError(msg)
    t, twist = _check_commands(t_s, vx_mps, vy_mps, wz_radps)
    n = len(t)
    if n == 0:
        return []
    moving = (np.abs(twist[:, 0]) > linear_tol_mps) | (np.abs(twist[:, 1]) > linear_tol_mps)
    moving |= np.abs(twist[:, 2]) > angular_tol_radps
    hold = np.diff(t, append=t[-1])  # zero-order hold; the last sample ends the recording
    typical = float(np.median(hold[:-1])) if n > 1 else 0.0
    weight = hold.copy()
    weight[-1] = typical  # so that a move of one last sample still has a kind

    segments: list[Segment] = []
    pending_gap: tuple[float, float] | None = None  # a short pause after the last move
    for i, j, is_moving in _runs(moving):
        t0, t1 = float(t[i]), float(t[min(j + 1, n - 1)])
        first, last = i == 0, j == n - 1
        if not is_moving:
            if t1 - t0 >= min_still_s:
                segments.append(Segment("still", t0, t1, 0, (0.0, 0.0, 0.0), first, last))
                pending_gap = None
            else:
                pending_gap = (t0, t1)
            continue
        kind, direction = _classify(twist[i : j + 1], weight[i : j + 1], yaw_lever_m, mixed_ratio)
        ix, iy, iw = (twist[i : j + 1] * hold[i : j + 1, None]).sum(axis=0)
        integral = (float(ix), float(iy), float(iw))
        prev = segments[-1] if segments else None
        if (
            pending_gap is not None
            and prev is not None
            and prev.kind == kind
            and prev.kind != "still"
            and prev.t_end_s == pending_gap[0]
        ):
            px, py, pw = prev.commanded_integral
            merged = (px + integral[0], py + integral[1], pw + integral[2])
            segments[-1] = replace(prev, t_end_s=t1, commanded_integral=merged, truncated_end=last)
        else:
            segments.append(Segment(kind, t0, t1, direction, integral, first, last))
        pending_gap = None
    return segments


def settled(segment: Segment, settle_s: float) -> Segment:
    """Drop the first ``settle_s`` of a stand-still (the robot still decelerates, the IPS lags).

    Args:
        segment: a ``still`` segment.
        settle_s: time to drop at its start, in s (≥ 0).

    Returns:
        The same stand-still starting ``settle_s`` later.

    Raises:
        CalibrationError: the segment is not a stand-still, ``settle_s`` is negative, or the
            stand-still is not longer than ``settle_s``.
    """
    if segment.kind != "still":
        msg = f"only a still segment can settle, got {segment.kind}"
        raise CalibrationError(msg)
    if settle_s < 0.0:
        msg = f"settle_s must be ≥ 0, got {settle_s}"
        raise CalibrationError(msg)
    if settle_s >= segment.duration_s:
        msg = (
            f"the stand-still at {segment.t_start_s:.3f} s lasts {segment.duration_s:.3f} s, "
            f"not more than settle_s = {settle_s:.3f} s"
        )
        raise CalibrationError(msg)
    truncated = segment.truncated_start and settle_s == 0.0
    return replace(segment, t_start_s=segment.t_start_s + settle_s, truncated_start=truncated)


def segment_mask(t_s: ArrayLike, segment: Segment) -> NDArray[np.bool_]:
    """Which samples of another stream (IPS fixes, odometry) fall in a segment.

    Args:
        t_s: (M,) sample times in s, in the time base of the commands.
        segment: the segment.

    Returns:
        (M,) True where t_start_s ≤ t ≤ t_end_s.
    """
    t = np.asarray(t_s, dtype=np.float64)
    return np.asarray((t >= segment.t_start_s) & (t <= segment.t_end_s), dtype=np.bool_)
