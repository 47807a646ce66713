"""Wheel odometry against ground truth, on a recording of the twin.

The ground truth (``map`` frame) is brought into the odometry frame by the pose at the first
odometry sample (origin alignment: both trajectories start at the same pose), interpolated at
the odometry times (linear in x, y and unwrapped yaw, not nearest neighbour), and compared.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from omnical.recording.recording import Recording

__all__ = ["OdometryErrors", "odometry_vs_ground_truth"]


@dataclass(frozen=True)
class OdometryErrors:
    """How far the wheel odometry drifted from the truth.

    Attributes:
        distance_odom_m: path length by odometry.
        distance_true_m: path length by ground truth.
        rmse_m: root-mean-square position error over the run.
        max_m: largest position error.
        final_m: position error at the end.
        final_heading_rad: heading error at the end (odometry − truth), wrapped to (−π, π].
        errors_m: (N,) position error at every odometry sample.
    """

    distance_odom_m: float
    distance_true_m: float
    rmse_m: float
    max_m: float
    final_m: float
    final_heading_rad: float
    errors_m: NDArray[np.float64]


def _path_length(x: NDArray[np.float64], y: NDArray[np.float64]) -> float:
    return float(np.sum(np.hypot(np.diff(x), np.diff(y))))


def odometry_vs_ground_truth(recording: Recording) -> OdometryErrors:
    """Compare ``/odom`` with ``/ground_truth`` (origin-aligned, interpolated at odometry times)."""
    odom = recording.topic("/odom")
    gt = recording.topic("/ground_truth")
    t_o = odom.t_ns
    t_g = gt.t_ns
    t0 = int(min(t_o[0], t_g[0]))
    to = (t_o - t0) * 1e-9
    tg = (t_g - t0) * 1e-9
    gx = np.interp(to, tg, gt["x_m"])
    gy = np.interp(to, tg, gt["y_m"])
    gyaw = np.interp(to, tg, np.unwrap(gt["yaw_rad"]))
    # align: rotate/translate the truth so its first pose equals the first odometry pose
    ox, oy, oyaw = odom["x_m"], odom["y_m"], np.unwrap(odom["yaw_rad"])
    dyaw = oyaw[0] - gyaw[0]
    c, s = np.cos(dyaw), np.sin(dyaw)
    dx, dy = gx - gx[0], gy - gy[0]
    ax = ox[0] + c * dx - s * dy
    ay = oy[0] + s * dx + c * dy
    ayaw = gyaw + dyaw
    err = np.hypot(ox - ax, oy - ay)
    heading = float(np.angle(np.exp(1j * (oyaw[-1] - ayaw[-1]))))
    return OdometryErrors(
        distance_odom_m=_path_length(ox, oy),
        distance_true_m=_path_length(gt["x_m"], gt["y_m"]),
        rmse_m=float(np.sqrt(np.mean(err**2))),
        max_m=float(err.max()),
        final_m=float(err[-1]),
        final_heading_rad=heading,
        errors_m=err,
    )
