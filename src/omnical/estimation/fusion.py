"""Wheel odometry fused with IPS position fixes: a small extended Kalman filter in SE(2).

:class:`FusedPoseSource` runs it as the ``pose_source`` of
:func:`omnical.control.loop.run_controller`, fed by any :class:`FixSource`.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import Pose2, between, interpolate_pose, rotate, wrap_angle
from omnical.experiment.ports import RobotState

__all__ = [
    "FixSource",
    "FusedPoseSource",
    "FusionParams",
    "FusionState",
    "IpsFix",
    "fusion_predict",
    "fusion_update",
    "initial_pose_from_fixes",
]

F64 = NDArray[np.float64]

#: χ²(2) quantile 0.999: fixes further than this (squared Mahalanobis distance) are rejected.
CHI2_2DOF_999 = 13.8155


def _finite_nonneg(name: str, value: float) -> None:
    if not (math.isfinite(value) and value >= 0.0):
        msg = f"{name} must be finite and >= 0, got {value}"
        raise ConfigError(msg)


@dataclass(frozen=True)
class FusionParams:
    """Noise model and settings of the odometry + IPS filter.

    Attributes:
        hedge_offset_m: hedgehog (x, y) in base_link, m.
        ips_sigma_m: standard deviation of a fix per axis, m.
        odom_trans_sigma_per_m: σ of each body-axis increment per metre travelled.
        odom_yaw_sigma_per_rad: σ of the yaw increment per radian turned.
        odom_yaw_sigma_per_m: σ of the yaw increment per metre travelled (cross-talk), rad/m.
        position_random_walk_m: position random walk, m/√s (keeps a standing filter open).
        yaw_random_walk_rad: yaw random walk, rad/√s.
        gate_chi2: squared Mahalanobis distance above which a fix is rejected (inf = no gate).
        history_s: how far back a delayed fix may reach, s.
        initial_yaw_sigma_rad: σ of the initial yaw (the start heading is known to about this).

    Raises:
        ConfigError: on construction, for a negative or non-finite noise value, a non-positive
            IPS σ, gate or history.
    """

    hedge_offset_m: tuple[float, float] = (0.0, 0.0)
    ips_sigma_m: float = 0.03
    odom_trans_sigma_per_m: float = 0.05
    odom_yaw_sigma_per_rad: float = 0.05
    odom_yaw_sigma_per_m: float = 0.05
    position_random_walk_m: float = 0.002
    yaw_random_walk_rad: float = 0.002
    gate_chi2: float = CHI2_2DOF_999
    history_s: float = 2.0
    initial_yaw_sigma_rad: float = 0.05

    def __post_init__(self) -> None:
        if len(self.hedge_offset_m) != 2 or not all(math.isfinite(v) for v in self.hedge_offset_m):
            msg = f"hedge_offset_m must be 2 finite numbers (x, y), got {self.hedge_offset_m}"
            raise ConfigError(msg)
        for name in (
            "odom_trans_sigma_per_m",
            "odom_yaw_sigma_per_rad",
            "odom_yaw_sigma_per_m",
            "position_random_walk_m",
            "yaw_random_walk_rad",
            "initial_yaw_sigma_rad",
        ):
            _finite_nonneg(name, getattr(self, name))
        for name in ("ips_sigma_m", "gate_chi2", "history_s"):
            value = getattr(self, name)
            if not value > 0.0:
                msg = f"{name} must be > 0, got {value}"
                raise ConfigError(msg)


@dataclass(frozen=True, eq=False)
class FusionState:
    """Filter state: the map-frame pose and its covariance.

    Attributes:
        pose: (x m, y m, yaw rad) of base_link in map (yaw continuous, not wrapped).
        cov: (3, 3) covariance of (x, y, yaw).
    """

    pose: Pose2
    cov: F64

    @classmethod
    def initial(cls, pose: Pose2, sigma: tuple[float, float, float]) -> FusionState:
        """A state at ``pose`` with independent standard deviations ``sigma`` (x, y, yaw)."""
        return cls(pose, np.diag(np.square(np.asarray(sigma, dtype=np.float64))))


def fusion_predict(
    params: FusionParams, state: FusionState, increment: Pose2, dt_s: float
) -> FusionState:
    """Propagate the state by an odometry increment.

    Args:
        params: noise model.
        state: state at the start of the increment.
        increment: (dx m, dy m, dyaw rad) of the odometry in the body frame at the start;
            the yaw change is wrapped to ±π (increments are one sample apart).
        dt_s: duration of the increment (for the random walk), ≥ 0.

    Returns:
        The predicted state.
    """
    x, y, yaw = state.pose
    dx, dy = increment[0], increment[1]
    dth = wrap_angle(increment[2])  # odometry yaw may be wrapped to ±π between samples
    c, s = math.cos(yaw), math.sin(yaw)
    pose = (x + c * dx - s * dy, y + s * dx + c * dy, yaw + dth)
    F = np.array([[1.0, 0.0, -s * dx - c * dy], [0.0, 1.0, c * dx - s * dy], [0.0, 0.0, 1.0]])
    G = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    dist = math.hypot(dx, dy)
    dt = max(dt_s, 0.0)
    var_t = (params.odom_trans_sigma_per_m * dist) ** 2 + params.position_random_walk_m**2 * dt
    sig_yaw = params.odom_yaw_sigma_per_rad * abs(dth) + params.odom_yaw_sigma_per_m * dist
    var_yaw = sig_yaw**2 + params.yaw_random_walk_rad**2 * dt
    Q = np.diag([var_t, var_t, var_yaw])
    cov = F @ state.cov @ F.T + G @ Q @ G.T
    return FusionState(pose, 0.5 * (cov + cov.T))


def fusion_update(
    params: FusionParams,
    state: FusionState,
    fix_xy_m: tuple[float, float],
    back: Pose2 = (0.0, 0.0, 0.0),
) -> tuple[FusionState, bool]:
    """Correct the state with one hedgehog position fix.

    Args:
        params: noise model and hedgehog offset.
        state: current state.
        fix_xy_m: measured hedgehog (x, y) in map, m.
        back: ⊖odom(now) ⊕ odom(t_meas), the motion back to the measurement time; zero for a
            fix without latency.

    Returns:
        ``(new_state, accepted)``; a fix outside the gate leaves the state unchanged.
    """
    x, y, yaw = state.pose
    bx, by, bth = back
    c, s = math.cos(yaw), math.sin(yaw)
    yaw_m = yaw + bth
    cm, sm = math.cos(yaw_m), math.sin(yaw_m)
    ox, oy = params.hedge_offset_m
    hx = x + c * bx - s * by + cm * ox - sm * oy
    hy = y + s * bx + c * by + sm * ox + cm * oy
    H = np.array(
        [
            [1.0, 0.0, -s * bx - c * by - sm * ox - cm * oy],
            [0.0, 1.0, c * bx - s * by + cm * ox - sm * oy],
        ]
    )
    nu = np.array([fix_xy_m[0] - hx, fix_xy_m[1] - hy])
    R = np.eye(2) * params.ips_sigma_m**2
    P = state.cov
    S = H @ P @ H.T + R
    S_inv = np.linalg.inv(S)
    if float(nu @ S_inv @ nu) > params.gate_chi2:
        return state, False
    K = P @ H.T @ S_inv
    dx = K @ nu
    I_KH = np.eye(3) - K @ H
    cov = I_KH @ P @ I_KH.T + K @ R @ K.T
    pose = (x + float(dx[0]), y + float(dx[1]), yaw + float(dx[2]))
    return FusionState(pose, 0.5 * (cov + cov.T)), True


def initial_pose_from_fixes(
    fixes: Sequence[IpsFix], yaw_rad: float, hedge_offset_m: tuple[float, float]
) -> Pose2:
    """The start pose from fixes taken while standing, with a known start heading (seed 000 Fig. 4).

    Args:
        fixes: fixes taken at rest.
        yaw_rad: start heading in map.
        hedge_offset_m: hedgehog (x, y) in base_link.

    Returns:
        (x, y, yaw) of base_link in map: the mean fix minus the turned hedgehog offset.

    Raises:
        ConfigError: no fixes.
    """
    if not fixes:
        msg = "cannot initialise the pose from the IPS: no fixes received"
        raise ConfigError(msg)
    mx = sum(f.x_m for f in fixes) / len(fixes)
    my = sum(f.y_m for f in fixes) / len(fixes)
    dx, dy = rotate(yaw_rad, *hedge_offset_m)
    return (mx - dx, my - dy, yaw_rad)


# --------------------------------------------------------------------------- online


@dataclass(frozen=True)
class IpsFix:
    """One hedgehog position fix.

    Attributes:
        t_meas_s: when the position was measured (clock time).
        t_arrival_s: when it reached the controller.
        x_m, y_m: hedgehog position in map.
    """

    t_meas_s: float
    t_arrival_s: float
    x_m: float
    y_m: float


class FixSource(Protocol):
    """Anything that hands over the fixes that have arrived since the last call."""

    def poll(self) -> list[IpsFix]:
        """Fixes arrived since the previous poll, oldest first."""


class FusedPoseSource:
    """The fused estimate as a loop pose source: ``RobotState → pose in the path frame``.

    Each call predicts with the odometry since the previous call, applies the fixes that have
    arrived (each at its measurement time) and returns the estimate in the path frame.
    """

    def __init__(
        self,
        params: FusionParams,
        fixes: FixSource,
        initial_pose_map: Pose2,
        *,
        path_origin_map: Pose2 = (0.0, 0.0, 0.0),
        initial_sigma: tuple[float, float, float] | None = None,
    ) -> None:
        self.params = params
        self._fixes = fixes
        sigma = initial_sigma or (
            params.ips_sigma_m,
            params.ips_sigma_m,
            params.initial_yaw_sigma_rad,
        )
        self._state = FusionState.initial(initial_pose_map, sigma)
        self._origin = path_origin_map
        self._hist_t: list[float] = []
        self._hist_pose: list[Pose2] = []
        self._log: list[tuple[float, float, float, float]] = []
        self.accepted = 0
        self.rejected = 0

    @property
    def state(self) -> FusionState:
        """The current filter state (map frame)."""
        return self._state

    def __call__(self, robot_state: RobotState) -> Pose2:
        """Update with the latest robot state and arrived fixes; the pose in the path frame."""
        t, odom = robot_state.t_s, robot_state.odom_pose
        if self._hist_t:
            self._state = fusion_predict(
                self.params, self._state, between(self._hist_pose[-1], odom), t - self._hist_t[-1]
            )
        self._hist_t.append(t)
        self._hist_pose.append(odom)
        cut = bisect.bisect_left(self._hist_t, t - self.params.history_s)
        if cut > 0:
            del self._hist_t[:cut]
            del self._hist_pose[:cut]
        for fix in self._fixes.poll():
            if fix.t_meas_s < self._hist_t[0] - 1e-9 and len(self._hist_t) > 1:
                self.rejected += 1
                continue
            back = between(odom, interpolate_pose(self._hist_t, self._hist_pose, fix.t_meas_s))
            self._state, ok = fusion_update(self.params, self._state, (fix.x_m, fix.y_m), back)
            if ok:
                self.accepted += 1
            else:
                self.rejected += 1
        pose = self._state.pose
        self._log.append((t, *pose))
        return between(self._origin, pose)

    def estimates(self) -> F64:
        """(N, 4) t_s, x, y, yaw of every estimate so far, map frame."""
        return np.array(self._log, dtype=np.float64).reshape(-1, 4)
