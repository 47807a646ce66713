"""Planar rigid motions (SE(2)): one home for composing, inverting, rotating, interpolating poses.

Poses ``(x m, y m, yaw rad)``; ``compose(a, b)`` = a ⊕ b, ``between(a, b)`` = ⊖a ⊕ b. Float forms
for one pose a tick, ``*_poses`` forms on broadcast arrays; composition never wraps a yaw.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import GeometryError

__all__ = [
    "Pose2",
    "Twist",
    "between",
    "between_poses",
    "body_increments",
    "compose",
    "compose_poses",
    "integrate_increments",
    "interpolate_pose",
    "interpolate_poses",
    "invert",
    "invert_poses",
    "rotate",
    "rotate_xy",
    "transform_point",
    "transform_points",
    "wrap_angle",
    "wrap_angles",
]

Pose2 = tuple[float, float, float]
"""(x m, y m, yaw rad) of a frame in its parent."""

Twist = tuple[float, float, float]
"""(vx m/s, vy m/s, wz rad/s) in base_link."""

FloatArray = NDArray[np.float64]

_TWO_PI = 2.0 * math.pi


# --------------------------------------------------------------------------- floats


def wrap_angle(angle_rad: float) -> float:
    """The angle in [−π, π] (IEEE remainder by 2π: exact, ties to the even multiple)."""
    return math.remainder(angle_rad, _TWO_PI)


def rotate(angle_rad: float, x: float, y: float) -> tuple[float, float]:
    """The vector (x, y) turned counter-clockwise by ``angle_rad``."""
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return c * x - s * y, s * x + c * y


def compose(a: Pose2, b: Pose2) -> Pose2:
    """a ⊕ b: pose ``b`` (given in the frame of ``a``) in the parent frame of ``a``.

    The yaw is not wrapped, so a continuous yaw stays continuous.
    """
    dx, dy = rotate(a[2], b[0], b[1])
    return (a[0] + dx, a[1] + dy, a[2] + b[2])


def invert(a: Pose2) -> Pose2:
    """⊖a: the parent frame seen from ``a``."""
    x, y = rotate(-a[2], -a[0], -a[1])
    return (x, y, -a[2])


def between(a: Pose2, b: Pose2) -> Pose2:
    """⊖a ⊕ b: pose ``b`` expressed in the frame of ``a`` (both given in the same parent)."""
    dx, dy = rotate(-a[2], b[0] - a[0], b[1] - a[1])
    return (dx, dy, b[2] - a[2])


def transform_point(a: Pose2, x: float, y: float) -> tuple[float, float]:
    """The point (x, y), given in the frame of ``a``, in the parent frame of ``a``."""
    dx, dy = rotate(a[2], x, y)
    return a[0] + dx, a[1] + dy


def interpolate_pose(t_s: Sequence[float], poses: Sequence[Pose2], t: float) -> Pose2:
    """The pose at ``t`` between ``poses`` taken at the non-decreasing times ``t_s``.

    Linear between the two samples around ``t``, the yaw by its wrapped difference (so the result
    is not wrapped); before the first or after the last sample, that sample itself.
    """
    i = bisect.bisect_right(t_s, t)
    if i == 0:
        return poses[0]
    if i == len(t_s):
        return poses[-1]
    t0, t1 = t_s[i - 1], t_s[i]
    a, b = poses[i - 1], poses[i]
    w = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
    return (a[0] + w * (b[0] - a[0]), a[1] + w * (b[1] - a[1]), a[2] + w * wrap_angle(b[2] - a[2]))


# --------------------------------------------------------------------------- arrays


def _last_axis(values: ArrayLike, size: int, what: str) -> FloatArray:
    array = np.asarray(values, dtype=np.float64)
    if array.ndim == 0 or array.shape[-1] != size:
        msg = f"{what} must have a last axis of length {size}, got shape {array.shape}"
        raise GeometryError(msg)
    return array


def _rotated(angle_rad: FloatArray, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return c * x - s * y, s * x + c * y


def wrap_angles(angles_rad: ArrayLike) -> FloatArray:
    """Angles in [−π, π], element by element exactly :func:`wrap_angle` (NaN for ±inf, NaN)."""
    a = np.asarray(angles_rad, dtype=np.float64)
    with np.errstate(invalid="ignore"):  # ±inf → NaN, as documented
        r = np.fmod(a, _TWO_PI)
    r = np.where(r > math.pi, r - _TWO_PI, np.where(r < -math.pi, r + _TWO_PI, r))
    tie = np.abs(r) == math.pi
    if np.any(tie):
        r[tie] = [math.remainder(float(v), _TWO_PI) for v in a[tie]]
    return r


def interpolate_poses(t_s: ArrayLike, poses: ArrayLike, at_s: ArrayLike) -> FloatArray:
    """(K, 3) poses (N, 3) taken at the increasing times ``t_s`` (N,), linear at ``at_s`` (K,).

    The yaw is unwrapped, interpolated and wrapped into [−π, π); outside ``t_s`` the first or
    last pose.
    """
    t = np.asarray(t_s, dtype=np.float64)
    p = np.asarray(poses, dtype=np.float64)
    at = np.asarray(at_s, dtype=np.float64)
    yaw = np.unwrap(p[:, 2])
    out = np.column_stack(
        [np.interp(at, t, p[:, 0]), np.interp(at, t, p[:, 1]), np.interp(at, t, yaw)]
    )
    out[:, 2] = (out[:, 2] + np.pi) % _TWO_PI - np.pi
    return out


def rotate_xy(angle_rad: ArrayLike, xy: ArrayLike) -> FloatArray:
    """Vectors (..., 2) turned counter-clockwise by ``angle_rad`` (scalar or (...,), broadcast).

    Raises:
        GeometryError: ``xy`` does not end in an axis of length 2.
    """
    v = _last_axis(xy, 2, "xy")
    x, y = _rotated(np.asarray(angle_rad, dtype=np.float64), v[..., 0], v[..., 1])
    return np.stack([x, y], axis=-1)


def compose_poses(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """a ⊕ b for poses (..., 3), broadcast: b (given in the frame of a) in a's parent frame.

    Raises:
        GeometryError: a pose array does not end in an axis of length 3.
    """
    pa, pb = _last_axis(a, 3, "a"), _last_axis(b, 3, "b")
    dx, dy = _rotated(pa[..., 2], pb[..., 0], pb[..., 1])
    return np.stack([pa[..., 0] + dx, pa[..., 1] + dy, pa[..., 2] + pb[..., 2]], axis=-1)


def invert_poses(a: ArrayLike) -> FloatArray:
    """⊖a for poses (..., 3): the parent frame seen from each pose.

    Raises:
        GeometryError: the array does not end in an axis of length 3.
    """
    pa = _last_axis(a, 3, "a")
    x, y = _rotated(-pa[..., 2], -pa[..., 0], -pa[..., 1])
    return np.stack([x, y, -pa[..., 2]], axis=-1)


def between_poses(a: ArrayLike, b: ArrayLike) -> FloatArray:
    """⊖a ⊕ b for poses (..., 3), broadcast: poses b expressed in the frame of a.

    Both are given in the same parent frame (one origin against a trajectory, or ``p[:-1]``
    against ``p[1:]`` for consecutive motions).

    Raises:
        GeometryError: a pose array does not end in an axis of length 3.
    """
    pa, pb = _last_axis(a, 3, "a"), _last_axis(b, 3, "b")
    dx, dy = _rotated(-pa[..., 2], pb[..., 0] - pa[..., 0], pb[..., 1] - pa[..., 1])
    return np.stack([dx, dy, pb[..., 2] - pa[..., 2]], axis=-1)


def transform_points(poses: ArrayLike, xy: ArrayLike) -> FloatArray:
    """Points (..., 2), given in the frames of ``poses`` (..., 3), in their parent frame.

    Broadcast: one pose against N points, or N poses against one point (a sensor's track).

    Raises:
        GeometryError: ``poses`` does not end in an axis of length 3 or ``xy`` in one of length 2.
    """
    p, v = _last_axis(poses, 3, "poses"), _last_axis(xy, 2, "xy")
    dx, dy = _rotated(p[..., 2], v[..., 0], v[..., 1])
    return np.stack([p[..., 0] + dx, p[..., 1] + dy], axis=-1)


def body_increments(poses_odom: ArrayLike) -> FloatArray:
    """Body-frame increments (dx m, dy m, dθ rad) between consecutive odometry poses.

    Args:
        poses_odom: (N, 3) x, y, yaw of base_link in the odom frame (yaw may be wrapped).

    Returns:
        (N − 1, 3) increments; the translation is expressed at the mid-interval heading.
    """
    p = np.asarray(poses_odom, dtype=np.float64)
    dtheta = wrap_angles(np.diff(p[:, 2]))
    mid = p[:-1, 2] + 0.5 * dtheta
    return np.column_stack([rotate_xy(-mid, np.diff(p[:, :2], axis=0)), dtheta])


def integrate_increments(start_pose: ArrayLike, increments: ArrayLike) -> FloatArray:
    """Compose body increments from a start pose.

    Args:
        start_pose: (3,) x, y, yaw at the first sample.
        increments: (M, 3) body-frame dx, dy, dθ.

    Returns:
        (M + 1, 3) poses (yaw not wrapped).
    """
    p0 = np.asarray(start_pose, dtype=np.float64)
    inc = np.asarray(increments, dtype=np.float64)
    yaw = p0[2] + np.concatenate([[0.0], np.cumsum(inc[:, 2])])
    step_xy = rotate_xy(yaw[:-1] + 0.5 * inc[:, 2], inc[:, :2])
    xy = p0[:2] + np.vstack([np.zeros((1, 2)), np.cumsum(step_xy, axis=0)])
    return np.column_stack([xy, yaw])
