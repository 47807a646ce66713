"""Seed 003's odometry (§II.C, Eq. 6–19): dead-wheel encoders, IMU yaw, complementary filter.

Generalised to any layout of three or more dead wheels and rotated per step; headings
counter-clockwise, z up (REP-103). The mapping onto the paper: docs/DESIGN-NOTES.md.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from omnical.errors import ConfigError
from omnical.estimation.se2 import rotate_xy
from omnical.robot.description import DeadWheel

__all__ = [
    "SEED003_HEADING_GAIN",
    "complementary_heading",
    "dead_wheel_body_increments",
    "dead_wheel_measurement_matrix",
    "dead_wheel_odometry",
    "magnetometer_yaw",
    "tilt_from_accelerometer",
]

F64 = NDArray[np.float64]

SEED003_HEADING_GAIN = 0.5
"""Weight of the encoder heading in seed 003's complementary filter (Eq. 17)."""


def tilt_from_accelerometer(acc_mps2: ArrayLike) -> tuple[F64, F64]:
    """Roll and pitch (rad) from the specific force (N, 3) of a resting IMU (seed 003 Eq. 7–8)."""
    a = np.asarray(acc_mps2, dtype=np.float64)
    roll = np.arctan2(a[:, 1], a[:, 2])
    pitch = np.arctan2(-a[:, 0], np.hypot(a[:, 1], a[:, 2]))
    return roll, pitch


def magnetometer_yaw(mag: ArrayLike, roll_rad: ArrayLike, pitch_rad: ArrayLike) -> F64:
    """Tilt-compensated magnetic yaw (rad, CCW from magnetic north = map +x), seed 003 Eq. 11.

    Args:
        mag: (N, 3) magnetic field in the body frame (any unit).
        roll_rad, pitch_rad: (N,) from :func:`tilt_from_accelerometer`.
    """
    m = np.asarray(mag, dtype=np.float64)
    phi = np.asarray(roll_rad, dtype=np.float64)
    theta = np.asarray(pitch_rad, dtype=np.float64)
    num = -m[:, 1] * np.cos(phi) + m[:, 2] * np.sin(phi)
    den = (
        m[:, 0] * np.cos(theta)
        + m[:, 1] * np.sin(theta) * np.sin(phi)
        + m[:, 2] * np.sin(theta) * np.cos(phi)
    )
    result: F64 = np.arctan2(num, den)
    return result


def dead_wheel_measurement_matrix(dead_wheels: Sequence[DeadWheel]) -> F64:
    """A (k, 3): each dead wheel's rolled distance from a body increment (dx, dy, dθ).

    Raises:
        ConfigError: the wheels cannot observe vx, vy and the yaw rate together (rank < 3).
    """
    rows = [
        (
            math.cos(d.direction_rad),
            math.sin(d.direction_rad),
            d.x_m * math.sin(d.direction_rad) - d.y_m * math.cos(d.direction_rad),
        )
        for d in dead_wheels
    ]
    A = np.array(rows, dtype=np.float64)
    if A.shape[0] < 3 or np.linalg.matrix_rank(A) < 3:
        msg = f"dead wheels: {len(rows)} encoders cannot observe vx, vy and yaw rate together"
        raise ConfigError(msg)
    return A


def dead_wheel_body_increments(counts: ArrayLike, dead_wheels: Sequence[DeadWheel]) -> F64:
    """Body-frame increments (dx m, dy m, dθ rad), shape (N-1, 3), from cumulative counts (N, k).

    Each encoder's distance is counts / resolution × circumference (seed 003 Eq. 12–14).
    """
    c = np.asarray(counts, dtype=np.float64)
    if c.ndim != 2 or c.shape[1] != len(dead_wheels):
        msg = f"counts must be (N, {len(dead_wheels)}), got {c.shape}"
        raise ConfigError(msg)
    per_count = np.array([2.0 * math.pi * d.radius_m / d.counts_per_rev for d in dead_wheels])
    distances = np.diff(c, axis=0) * per_count
    A = dead_wheel_measurement_matrix(dead_wheels)
    result: F64 = np.linalg.lstsq(A, distances.T, rcond=None)[0].T
    return result


def complementary_heading(
    theta_encoder_rad: ArrayLike, yaw_imu_rad: ArrayLike, gain: float = SEED003_HEADING_GAIN
) -> F64:
    """ψ = gain · ϑ_rotary + (1 − gain) · φ_IMU (seed 003 Eq. 17), on unwrapped angles."""
    th = np.unwrap(np.asarray(theta_encoder_rad, dtype=np.float64))
    yi = np.unwrap(np.asarray(yaw_imu_rad, dtype=np.float64))
    yi = yi + 2.0 * math.pi * np.round((th[0] - yi[0]) / (2.0 * math.pi))
    result: F64 = gain * th + (1.0 - gain) * yi
    return result


def dead_wheel_odometry(
    counts: ArrayLike,
    dead_wheels: Sequence[DeadWheel],
    yaw_imu_rad: ArrayLike | None = None,
    *,
    gain: float = SEED003_HEADING_GAIN,
    start_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
) -> F64:
    """Poses (N, 3) from dead-wheel counts (N, k) and, optionally, IMU yaw (N,) at the same times.

    The heading is the encoders' own (integrated dθ) blended with the IMU yaw by the complementary
    filter; without an IMU yaw it is the encoders' alone. Increments are rotated by the heading at
    the middle of each step.
    """
    inc = dead_wheel_body_increments(counts, dead_wheels)
    theta_enc = start_pose[2] + np.concatenate([[0.0], np.cumsum(inc[:, 2])])
    if yaw_imu_rad is None:
        heading = theta_enc
    else:
        yi = np.asarray(yaw_imu_rad, dtype=np.float64)
        yi = yi - yi[0] + start_pose[2]
        heading = complementary_heading(theta_enc, yi, gain)
    mid = 0.5 * (heading[:-1] + heading[1:])
    step = rotate_xy(mid, inc[:, :2])
    x = start_pose[0] + np.concatenate([[0.0], np.cumsum(step[:, 0])])
    y = start_pose[1] + np.concatenate([[0.0], np.cumsum(step[:, 1])])
    return np.column_stack([x, y, heading])
