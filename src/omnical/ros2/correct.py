"""Live odometry correction: each raw increment (odometry poses or wheel angles) corrected by the
seven factors and composed, with the pose and twist covariances their 1σ imply.

Pure, one sample at a time (:func:`correct_pose_step`, :func:`correct_wheel_step`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.estimation.se2 import wrap_angle
from omnical.kinematics.correction import CorrectionFactors, counter_compensate_twist

__all__ = [
    "CorrectedOdometry",
    "body_increment",
    "correct_increment",
    "correct_pose_step",
    "correct_wheel_step",
    "factor_sigmas",
    "start_corrected",
]

_FACTOR_NAMES = tuple(f.name for f in fields(CorrectionFactors))


@dataclass(frozen=True)
class CorrectedOdometry:
    """The corrected odometry after a sample.

    Attributes:
        t_ns: time of the sample.
        pose: (x m, y m, yaw rad) corrected, in the raw odometry's frame, from its first pose.
        twist: (vx m/s, vy m/s, wz rad/s) corrected, in base_link (zero at the first sample).
        raw: the raw pose (odometry) or wheel angles (rad) of the sample, for the next step.
        pose_sensitivity: (3, 7) d pose / d factors accumulated since the start.
        twist_sensitivity: (3, 7) d twist / d factors of the last step.
    """

    t_ns: int
    pose: tuple[float, float, float]
    twist: tuple[float, float, float]
    raw: tuple[float, ...]
    pose_sensitivity: NDArray[np.float64]
    twist_sensitivity: NDArray[np.float64]

    def pose_covariance(self, sigmas: ArrayLike) -> NDArray[np.float64]:
        """(3, 3) covariance of (x, y, yaw) from the factors' 1σ (7,)."""
        s2 = np.square(np.nan_to_num(np.asarray(sigmas, dtype=np.float64)))
        g = self.pose_sensitivity
        out: NDArray[np.float64] = (g * s2) @ g.T
        return out

    def twist_covariance(self, sigmas: ArrayLike) -> NDArray[np.float64]:
        """(3, 3) covariance of (vx, vy, wz) from the factors' 1σ (7,)."""
        s2 = np.square(np.nan_to_num(np.asarray(sigmas, dtype=np.float64)))
        g = self.twist_sensitivity
        out: NDArray[np.float64] = (g * s2) @ g.T
        return out


def factor_sigmas(uncertainty: CorrectionFactors | None) -> NDArray[np.float64]:
    """(7,) the factors' 1σ in :class:`CorrectionFactors` order (NaN or none → 0: not estimated)."""
    if uncertainty is None:
        return np.zeros(len(_FACTOR_NAMES))
    values = np.array([getattr(uncertainty, n) for n in _FACTOR_NAMES], dtype=np.float64)
    out: NDArray[np.float64] = np.nan_to_num(values)
    return out


def start_corrected(
    t_ns: int, raw: ArrayLike, pose: ArrayLike = (0.0, 0.0, 0.0)
) -> CorrectedOdometry:
    """The state at the first sample: the corrected pose starts at ``pose`` (default the origin;
    pass the raw pose to start where the raw odometry is)."""
    x, y, yaw = (float(v) for v in np.asarray(pose, dtype=np.float64))
    return CorrectedOdometry(
        t_ns=int(t_ns),
        pose=(x, y, yaw),
        twist=(0.0, 0.0, 0.0),
        raw=tuple(float(v) for v in np.asarray(raw, dtype=np.float64).ravel()),
        pose_sensitivity=np.zeros((3, len(_FACTOR_NAMES))),
        twist_sensitivity=np.zeros((3, len(_FACTOR_NAMES))),
    )


def body_increment(previous: ArrayLike, pose: ArrayLike) -> NDArray[np.float64]:
    """(3,) body-frame dx, dy (at the mid-step heading) and dθ from ``previous`` to ``pose``."""
    a = np.asarray(previous, dtype=np.float64)
    b = np.asarray(pose, dtype=np.float64)
    dyaw = wrap_angle(float(b[2] - a[2]))
    mid = a[2] + 0.5 * dyaw
    c, s = math.cos(mid), math.sin(mid)
    dx, dy = float(b[0] - a[0]), float(b[1] - a[1])
    return np.array([c * dx + s * dy, -s * dx + c * dy, dyaw])


def correct_increment(
    raw_increment: ArrayLike, factors: CorrectionFactors, installed: CorrectionFactors | None = None
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(3,) the corrected body increment of a raw one, and (3, 7) its derivative by the factors.

    ``installed``: the factors the raw odometry was already compensated with (undone first).
    """
    from omnical.kinematics.correction import compensate_twist

    inc = np.asarray(raw_increment, dtype=np.float64)
    nominal = compensate_twist(inc, installed) if installed is not None else inc
    real = counter_compensate_twist(nominal, factors)
    jac = np.zeros((3, len(_FACTOR_NAMES)))
    for j, name in enumerate(_FACTOR_NAMES):
        value = float(getattr(factors, name))
        h = 1e-6 * max(1.0, abs(value))
        up = counter_compensate_twist(nominal, replace(factors, **{name: value + h}))
        down = counter_compensate_twist(nominal, replace(factors, **{name: value - h}))
        jac[:, j] = (up - down) / (2.0 * h)
    return real, jac


def _compose(
    state: CorrectedOdometry,
    t_ns: int,
    raw: ArrayLike,
    real: NDArray[np.float64],
    jac: NDArray[np.float64],
) -> CorrectedOdometry:
    x, y, yaw = state.pose
    dx, dy, dth = (float(v) for v in real)
    mid = yaw + 0.5 * dth
    c, s = math.cos(mid), math.sin(mid)
    sx, sy = c * dx - s * dy, s * dx + c * dy
    # d(new pose)/d(old pose) and d(new pose)/d(increment) of the mid-heading composition
    a = np.array([[1.0, 0.0, -sy], [0.0, 1.0, sx], [0.0, 0.0, 1.0]])
    b = np.array([[c, -s, -0.5 * sy], [s, c, 0.5 * sx], [0.0, 0.0, 1.0]])
    dt_s = (int(t_ns) - state.t_ns) / 1e9
    twist = (dx / dt_s, dy / dt_s, dth / dt_s) if dt_s > 0.0 else state.twist
    return CorrectedOdometry(
        t_ns=int(t_ns),
        pose=(x + sx, y + sy, wrap_angle(yaw + dth)),
        twist=twist,
        raw=tuple(float(v) for v in np.asarray(raw, dtype=np.float64).ravel()),
        pose_sensitivity=a @ state.pose_sensitivity + b @ jac,
        twist_sensitivity=jac / dt_s if dt_s > 0.0 else state.twist_sensitivity,
    )


def correct_pose_step(
    state: CorrectedOdometry,
    t_ns: int,
    raw_pose: ArrayLike,
    factors: CorrectionFactors,
    installed: CorrectionFactors | None = None,
) -> CorrectedOdometry:
    """The state after a raw odometry pose (x, y, yaw) at ``t_ns`` (a sample not after the
    previous one changes nothing)."""
    if int(t_ns) <= state.t_ns:
        return state
    real, jac = correct_increment(body_increment(state.raw, raw_pose), factors, installed)
    return _compose(state, t_ns, raw_pose, real, jac)


def correct_wheel_step(
    state: CorrectedOdometry,
    t_ns: int,
    wheel_angles_rad: ArrayLike,
    J_plus: ArrayLike,
    factors: CorrectionFactors,
) -> CorrectedOdometry:
    """The state after wheel angles (rad, the description's wheel order) at ``t_ns``: their
    increments through the nominal forward kinematics ``J_plus`` (3, n), then corrected."""
    if int(t_ns) <= state.t_ns:
        return state
    angles = np.asarray(wheel_angles_rad, dtype=np.float64)
    nominal = np.asarray(J_plus, dtype=np.float64) @ (angles - np.asarray(state.raw))
    real, jac = correct_increment(nominal, factors)
    return _compose(state, t_ns, angles, real, jac)
