"""Time association of an estimated trajectory with a reference trajectory.

The reference is interpolated at the estimate's times (x, y, unwrapped yaw), never extrapolated
nor across a gap over ``max_gap_s``; times are float seconds from a common origin.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError

__all__ = ["Association", "Trajectory", "associate", "paired_xy"]

FloatArray = NDArray[np.float64]


def _float_array(values: ArrayLike) -> FloatArray:
    return np.asarray(values, dtype=np.float64)


def paired_xy(a_xy_m: ArrayLike, b_xy_m: ArrayLike, what: str) -> tuple[FloatArray, FloatArray]:
    """Two (N, 2) position arrays paired row by row, N ≥ 1, as float arrays.

    Args:
        a_xy_m: (N, 2) positions.
        b_xy_m: (N, 2) positions, row i paired with row i of ``a_xy_m``.
        what: the operation that needs them, for the messages.

    Raises:
        GeometryError: a shape is not (N, 2), the shapes differ, or N = 0.
    """
    a, b = _float_array(a_xy_m), _float_array(b_xy_m)
    if a.ndim != 2 or a.shape[1] != 2 or a.shape != b.shape:
        raise GeometryError(f"{what} needs two (N, 2) arrays, got {a.shape} and {b.shape}")
    if a.shape[0] == 0:
        raise GeometryError(f"{what} needs at least one pair of positions")
    return a, b


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A planar trajectory: times, positions and, when known, headings.

    The arrays are copied and made read-only, except those given read-only already (kept).

    Args:
        t_s: (N,) sample times in seconds, non-decreasing.
        xy_m: (N, 2) positions, metres, in ``frame``.
        yaw_rad: (N,) headings in radians (wrapped or not), or None (IPS positions).
        frame: name of the frame of the positions (``map``, ``odom``, ...), for messages.
        covariance_xy_m2: (N, 2, 2) position covariances (multilateration fixes), or None.

    Raises:
        GeometryError: shapes disagree, times are not finite and non-decreasing, or a position
            or heading is not finite.
    """

    t_s: FloatArray
    xy_m: FloatArray
    yaw_rad: FloatArray | None = None
    frame: str = ""
    covariance_xy_m2: FloatArray | None = None

    def __post_init__(self) -> None:
        t = _float_array(self.t_s)
        xy = _float_array(self.xy_m)
        if t.ndim != 1:
            raise GeometryError(f"trajectory times must be (N,), got shape {t.shape}")
        if xy.shape != (t.size, 2):
            raise GeometryError(f"trajectory positions must be ({t.size}, 2), got shape {xy.shape}")
        if not (np.all(np.isfinite(t)) and np.all(np.isfinite(xy))):
            raise GeometryError("trajectory times and positions must be finite")
        if t.size > 1 and bool(np.any(np.diff(t) < 0)):
            raise GeometryError("trajectory times must be non-decreasing")
        yaw = None
        if self.yaw_rad is not None:
            yaw = _float_array(self.yaw_rad)
            if yaw.shape != t.shape:
                raise GeometryError(f"trajectory headings must be ({t.size},), got {yaw.shape}")
            if not np.all(np.isfinite(yaw)):
                raise GeometryError("trajectory headings must be finite")
        cov = None
        if self.covariance_xy_m2 is not None:
            cov = _float_array(self.covariance_xy_m2)
            if cov.shape != (t.size, 2, 2):
                raise GeometryError(
                    f"trajectory covariances must be ({t.size}, 2, 2), got {cov.shape}"
                )
        arrays = (("t_s", t), ("xy_m", xy), ("yaw_rad", yaw), ("covariance_xy_m2", cov))
        for name, array in arrays:
            if array is not None and not _frozen(array):  # a frozen one is kept as given
                array = array.copy()
                array.setflags(write=False)
            object.__setattr__(self, name, array)

    def __len__(self) -> int:
        return int(self.t_s.size)

    def take(self, index: ArrayLike) -> Trajectory:
        """The samples selected by an index array or boolean mask, as a new trajectory."""
        i = np.asarray(index)
        yaw = None if self.yaw_rad is None else self.yaw_rad[i]
        cov = None if self.covariance_xy_m2 is None else self.covariance_xy_m2[i]
        return Trajectory(self.t_s[i], self.xy_m[i], yaw, self.frame, cov)


def _frozen(array: np.ndarray) -> bool:
    """The array and every array it views are read-only."""
    base: object = array
    while isinstance(base, np.ndarray):
        if base.flags.writeable:
            return False
        base = base.base
    return base is None or isinstance(base, bytes)


@dataclass(frozen=True, eq=False)
class Association:
    """Estimate samples paired with the reference interpolated at their times.

    Attributes:
        t_s: (M,) times of the kept estimate samples, seconds.
        index: (M,) indices of the kept samples in the estimate.
        estimate_xy_m: (M, 2) estimated positions (estimate frame).
        reference_xy_m: (M, 2) reference positions interpolated at ``t_s`` (reference frame).
        estimate_yaw_rad: (M,) estimated headings, unwrapped over the kept samples, or None.
        reference_yaw_rad: (M,) reference headings interpolated in the unwrapped angle, or None.
        estimate_covariance_xy_m2: (M, 2, 2) covariances of the kept samples (estimate frame),
            or None.
    """

    t_s: FloatArray
    index: NDArray[np.int64]
    estimate_xy_m: FloatArray
    reference_xy_m: FloatArray
    estimate_yaw_rad: FloatArray | None
    reference_yaw_rad: FloatArray | None
    estimate_covariance_xy_m2: FloatArray | None = None

    def __len__(self) -> int:
        return int(self.t_s.size)


def _kept(t_est: FloatArray, t_ref: FloatArray, max_gap_s: float | None) -> NDArray[np.bool_]:
    inside: NDArray[np.bool_] = (t_est >= t_ref[0]) & (t_est <= t_ref[-1])
    if max_gap_s is None or t_ref.size < 2:
        return inside
    k = np.clip(np.searchsorted(t_ref, t_est, side="right") - 1, 0, t_ref.size - 1)
    on_sample = t_ref[k] == t_est
    upper = np.minimum(k + 1, t_ref.size - 1)
    short = (t_ref[upper] - t_ref[k]) <= max_gap_s
    kept: NDArray[np.bool_] = inside & (on_sample | short)
    return kept


def associate(
    estimate: Trajectory, reference: Trajectory, *, max_gap_s: float | None = None
) -> Association:
    """Pair every estimate sample inside the reference's time span with the interpolated reference.

    Args:
        estimate: the trajectory to evaluate.
        reference: the trajectory to compare against; its times must be strictly increasing.
        max_gap_s: drop estimate samples that fall between two reference samples further apart
            than this (None: no limit).

    Returns:
        The kept samples in time order; headings only when both trajectories have them.

    Raises:
        GeometryError: the reference has fewer than one sample, repeated times, or no estimate
            sample falls inside it; ``max_gap_s`` is not positive.
    """
    if max_gap_s is not None and not max_gap_s > 0:
        raise GeometryError(f"max_gap_s must be positive, got {max_gap_s}")
    t_ref = reference.t_s
    if t_ref.size == 0:
        raise GeometryError("the reference trajectory is empty")
    if t_ref.size > 1 and bool(np.any(np.diff(t_ref) <= 0)):
        raise GeometryError("reference times must be strictly increasing (repeated time stamps)")
    kept = _kept(estimate.t_s, t_ref, max_gap_s)
    index = np.flatnonzero(kept).astype(np.int64)
    if index.size == 0:
        span = f"{t_ref[0]:.3f}..{t_ref[-1]:.3f} s"
        raise GeometryError(f"no estimate sample lies inside the reference ({span}, gaps)")
    # every sample kept (the usual case): the estimate's own arrays, not copies of them
    rows: NDArray[np.int64] | slice = slice(None) if index.size == kept.size else index
    t = estimate.t_s[rows]
    ref_xy = np.column_stack(
        [np.interp(t, t_ref, reference.xy_m[:, 0]), np.interp(t, t_ref, reference.xy_m[:, 1])]
    )
    est_yaw = ref_yaw = None
    if estimate.yaw_rad is not None and reference.yaw_rad is not None:
        est_yaw = np.unwrap(estimate.yaw_rad[rows])
        ref_yaw = np.interp(t, t_ref, np.unwrap(reference.yaw_rad))
    return Association(
        t_s=t,
        index=index,
        estimate_xy_m=estimate.xy_m[rows],
        reference_xy_m=ref_xy,
        estimate_yaw_rad=est_yaw,
        reference_yaw_rad=ref_yaw,
        estimate_covariance_xy_m2=(
            None if estimate.covariance_xy_m2 is None else estimate.covariance_xy_m2[rows]
        ),
    )
