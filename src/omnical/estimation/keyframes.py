"""Odometry preintegrated between keyframes, and the full-rate poses bridged back from them.

:func:`preintegrate` composes the increments between keyframes for the batch smoother (covariance
and correction design carried through); :func:`bridge` recovers every sample between two keyframes.
"""

from __future__ import annotations

from typing import Final

import numpy as np
from numpy.typing import NDArray

from omnical.estimation.se2 import between_poses

__all__ = [
    "bridge",
    "increment_design",
    "keyframe_indices",
    "keyframes_by_time",
    "odometry_increments",
    "preintegrate",
]

F64 = NDArray[np.float64]

_INTERVALS: Final = 512
"""Keyframe intervals handled at a time (bounds the temporaries)."""


def increment_design(inc: F64) -> F64:
    """(K, 3, 7): how the scale/cross-talk corrections change each body increment."""
    k = inc.shape[0]
    g = np.zeros((k, 3, 7))
    dx, dy, dth = inc[:, 0], inc[:, 1], inc[:, 2]
    g[:, 0, 0] = dx
    g[:, 1, 1] = dy
    g[:, 2, 2] = dth
    g[:, 2, 3] = np.maximum(dx, 0.0)
    g[:, 2, 4] = np.maximum(-dx, 0.0)
    g[:, 2, 5] = np.maximum(dy, 0.0)
    g[:, 2, 6] = np.maximum(-dy, 0.0)
    return g


def odometry_increments(
    od: F64,
    trans_sigma_per_m: float,
    yaw_sigma_per_rad: float,
    yaw_sigma_per_m: float,
    position_random_walk_m: float,
    yaw_random_walk_rad: float,
) -> tuple[F64, F64]:
    """Body increments (K, 3) between consecutive rows of ``od`` (t, x, y, yaw) and their σ (K, 3).

    The yaw increment is the wrapped difference; σ grows with distance, turn and time.
    """
    inc = between_poses(od[:-1, 1:], od[1:, 1:])
    inc[:, 2] = np.angle(np.exp(1j * (od[1:, 3] - od[:-1, 3])))
    dist = np.hypot(inc[:, 0], inc[:, 1])
    dt = np.diff(od[:, 0])
    sig_t = np.sqrt((trans_sigma_per_m * dist) ** 2 + position_random_walk_m**2 * dt)
    sig_yaw = np.sqrt(
        (yaw_sigma_per_rad * np.abs(inc[:, 2]) + yaw_sigma_per_m * dist) ** 2
        + yaw_random_walk_rad**2 * dt
    )
    return inc, np.column_stack([sig_t, sig_t, sig_yaw])


def keyframe_indices(n: int, stride: int) -> NDArray[np.intp]:
    """Every ``stride``-th of ``n`` samples, the last one always included."""
    idx = np.arange(0, n, max(1, stride), dtype=np.intp)
    if idx[-1] != n - 1:
        idx = np.append(idx, np.intp(n - 1))
    return idx


def keyframes_by_time(t_s: F64, interval_s: float) -> NDArray[np.intp]:
    """The first sample of every ``interval_s`` of elapsed time from the first (and the last)."""
    t = np.asarray(t_s, dtype=np.float64)
    if t.size < 2:
        return np.arange(t.size, dtype=np.intp)
    bins = np.floor((t - t[0]) / interval_s + 1e-9)  # + 1e-9: k·dt on a boundary stays on it
    idx = np.concatenate([[0], np.flatnonzero(np.diff(bins) > 0) + 1]).astype(np.intp)
    if idx[-1] != t.size - 1:
        idx = np.append(idx, np.intp(t.size - 1))
    return idx


def _composite(inc: F64, starts: NDArray[np.intp]) -> tuple[F64, F64, F64]:
    """Each segment's composite of the body increments ``inc`` (rows ``starts[i]`` to the next
    start; ``starts[0] == 0``): the Jacobian J_j (L, 3, 3) of the composite with respect to every
    sub-increment, and the composite's translation (S, 2) and turn (S,) in the segment's frame."""
    ends = np.append(starts[1:], inc.shape[0]) - 1
    seg = np.repeat(np.arange(starts.size), ends - starts + 1)
    cum_yaw = np.cumsum(inc[:, 2])
    yaw_before = np.concatenate([[0.0], cum_yaw[ends[:-1]]])
    phi = cum_yaw - inc[:, 2] - yaw_before[seg]  # heading before each sub-increment
    c, s = np.cos(phi), np.sin(phi)
    cum = np.cumsum(
        np.column_stack([c * inc[:, 0] - s * inc[:, 1], s * inc[:, 0] + c * inc[:, 1]]), axis=0
    )
    before = np.concatenate([np.zeros((1, 2)), cum[ends[:-1]]])
    trans = cum[ends] - before
    lever = trans[seg] - (cum - before[seg])  # t − p_{j+1}
    jac = np.zeros((inc.shape[0], 3, 3))
    jac[:, 0, 0], jac[:, 0, 1], jac[:, 0, 2] = c, -s, -lever[:, 1]
    jac[:, 1, 0], jac[:, 1, 1], jac[:, 1, 2] = s, c, lever[:, 0]
    jac[:, 2, 2] = 1.0
    return jac, trans, cum_yaw[ends] - yaw_before


def _covariances(jac: F64, sig: F64, starts: NDArray[np.intp]) -> F64:
    """Σ_K = Σ_j J_j diag(σ_j²) J_jᵀ of every segment."""
    out: F64 = np.add.reduceat(
        (jac * sig[:, None, :] ** 2) @ np.swapaxes(jac, 1, 2), starts, axis=0
    )
    return out


SigmaArgs = tuple[float, float, float, float, float]
"""The five noise settings of :func:`odometry_increments`, in its order."""


def preintegrate(od: F64, idx: NDArray[np.intp], sigma_args: SigmaArgs) -> tuple[F64, F64, F64]:
    """Composite increments, their θ design and covariance between consecutive keyframes.

    Args:
        od: (N, 4) t, x, y, yaw of the odometry (times increasing).
        idx: (K,) keyframe rows of ``od`` (:func:`keyframe_indices`).
        sigma_args: the noise settings of :func:`odometry_increments`.

    Returns:
        inc (K − 1, 3), design (K − 1, 3, 7) and covariance (K − 1, 3, 3).
    """
    m = idx.size - 1
    inc_k = np.empty((m, 3))
    design_k = np.empty((m, 3, 7))
    cov_k = np.empty((m, 3, 3))
    for i0 in range(0, m, _INTERVALS):
        i1 = min(i0 + _INTERVALS, m)
        a, b = int(idx[i0]), int(idx[i1])
        inc, sig = odometry_increments(od[a : b + 1], *sigma_args)
        starts = idx[i0:i1] - a
        jac, trans, turn = _composite(inc, starts)
        design_k[i0:i1] = np.add.reduceat(jac @ increment_design(inc), starts, axis=0)
        cov_k[i0:i1] = _covariances(jac, sig, starts)
        inc_k[i0:i1, :2] = trans
        inc_k[i0:i1, 2] = turn
    return inc_k, design_k, cov_k


def bridge(
    od: F64,
    idx: NDArray[np.intp],
    sigma_args: SigmaArgs,
    key_poses: F64,
    key_cov: F64,
    theta: F64,
) -> tuple[F64, F64]:
    """The pose and covariance at every odometry sample from the smoothed keyframes.

    Args:
        od: (N, 4) t, x, y, yaw of the odometry.
        idx: (K,) keyframe rows of ``od``.
        sigma_args: the noise settings of :func:`odometry_increments`.
        key_poses: (K, 3) smoothed keyframe poses (yaw continuous).
        key_cov: (K, 3, 3) their marginal covariances.
        theta: (7,) the linear odometry correction found (scales, cross-talks).

    Returns:
        poses (N, 3) (yaw continuous; the keyframes' own rows are theirs) and covariances
        (N, 3, 3).
    """
    n = od.shape[0]
    poses = np.empty((n, 3))
    cov = np.empty((n, 3, 3))
    m = idx.size - 1
    for i0 in range(0, m, _INTERVALS):
        i1 = min(i0 + _INTERVALS, m)
        a, b = int(idx[i0]), int(idx[i1])
        inc, sig = odometry_increments(od[a : b + 1], *sigma_args)
        corrected = inc + increment_design(inc) @ theta
        starts = idx[i0:i1] - a
        ends = np.append(starts[1:], inc.shape[0]) - 1
        seg = np.repeat(np.arange(i1 - i0), ends - starts + 1)
        # dead reckoning of the corrected odometry from each interval's first keyframe, in map
        cum_yaw = np.cumsum(corrected[:, 2])
        yaw0 = key_poses[i0:i1, 2] - np.concatenate([[0.0], cum_yaw[ends[:-1]]])
        heading = yaw0[seg] + cum_yaw - corrected[:, 2]
        c, s = np.cos(heading), np.sin(heading)
        cum = np.cumsum(
            np.column_stack(
                [
                    c * corrected[:, 0] - s * corrected[:, 1],
                    s * corrected[:, 0] + c * corrected[:, 1],
                ]
            ),
            axis=0,
        )
        xy0 = key_poses[i0:i1, :2] - np.concatenate([np.zeros((1, 2)), cum[ends[:-1]]])
        dead = np.column_stack([xy0[seg] + cum, yaw0[seg] + cum_yaw])  # rows a + 1 … b
        closure = key_poses[i0 + 1 : i1 + 1] - dead[ends]
        # the closure spread by accumulated variance (of x, y and yaw each)
        var = np.cumsum(sig**2, axis=0)
        var_before = np.concatenate([np.zeros((1, 3)), var[ends[:-1]]])
        w = (var - var_before[seg]) / np.maximum(var[ends] - var_before, 1e-300)[seg]
        poses[a + 1 : b + 1] = dead + w * closure[seg]
        # the keyframes' covariance interpolated, plus the bridge's own w (1 − w) Σ_K in map
        jac, _, _ = _composite(inc, starts)
        q = _covariances(jac, sig, starts)
        rot = np.zeros((i1 - i0, 3, 3))
        cy, sy = np.cos(key_poses[i0:i1, 2]), np.sin(key_poses[i0:i1, 2])
        rot[:, 0, 0], rot[:, 0, 1], rot[:, 1, 0], rot[:, 1, 1] = cy, -sy, sy, cy
        rot[:, 2, 2] = 1.0
        q = rot @ q @ np.swapaxes(rot, 1, 2)
        wt = w[:, 0, None, None]
        cov[a + 1 : b + 1] = (
            (1.0 - wt) * key_cov[i0:i1][seg]
            + wt * key_cov[i0 + 1 : i1 + 1][seg]
            + (wt * (1.0 - wt)) * q[seg]
        )
    poses[idx] = key_poses  # the keyframes exactly
    cov[idx] = key_cov
    return poses, cov
